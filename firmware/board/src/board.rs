//! The board: every pin, clock, interrupt and peripheral choice of the
//! trueaxis compensation board (STM32F405RG, 8 MHz crystal) is in this file
//! and in memory.x — nowhere else. It also implements the application
//! core's hardware traits on those peripherals.
//!
//! | function | peripheral | pins |
//! | --- | --- | --- |
//! | X encoder (QEI) | TIM2 | PA15 (CH1), PB3 (CH2) |
//! | Y encoder (QEI) | TIM3 | PA6 (CH1), PA7 (CH2) |
//! | Z encoder (QEI) | TIM4 | PB6 (CH1), PB7 (CH2) |
//! | thermistors 0-3 | ADC1 IN10-13 | PC0-PC3 |
//! | X step / dir | GPIO | PB12 / PB13 |
//! | Y step / dir | GPIO | PB14 / PB15 |
//! | Z step / dir | GPIO | PC6 / PC7 |
//! | link, USB CDC-ACM | OTG_FS | PA12 (D+), PA11 (D−) |
//! | link, UART 115200 8N1 | USART1 | PA9 (TX), PA10 (RX) |
//! | embassy-time driver | TIM5 | — |
//! | correction executor | UART4 IRQ (unused UART, used as a software interrupt), priority P6 | — |
//!
//! SWD stays on PA13/PA14; PA15/PB3 give up JTAG's JTDI/JTDO (SWO is not
//! used: logs go over RTT).

use embassy_executor::{InterruptExecutor, SendSpawner};
use embassy_stm32::adc::{Adc, SampleTime};
use embassy_stm32::flash::{Blocking, Flash};
use embassy_stm32::gpio::{AnyPin, Input, Level, Output, Pull, Speed};
use embassy_stm32::interrupt::{self, InterruptExt, Priority};
use embassy_stm32::peripherals::{
    ADC1, IWDG, PC0, PC1, PC2, PC3, TIM2, TIM3, TIM4, USART1, USB_OTG_FS,
};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::qei::{Config as QeiConfig, Qei};
use embassy_stm32::usart::{self, BufferedUart};
use embassy_stm32::usb;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{bind_interrupts, interrupt as irq_attr, Peri, Peripherals};
use static_cell::StaticCell;

use trueaxis_app::engine::{Approach, AxisConfig, EngineConfig, HomeSwitch};
use trueaxis_app::hw::{Encoders, StepOutput};
use trueaxis_app::sensors::{Ntc, Widen16};
use trueaxis_app::store::Layout;

mod slots {
    include!(concat!(env!("OUT_DIR"), "/slots.rs"));
}

bind_interrupts!(pub struct Irqs {
    OTG_FS => usb::InterruptHandler<USB_OTG_FS>;
    USART1 => usart::BufferedInterruptHandler<USART1>;
});

/// The table slots of memory.x, as offsets for embassy-stm32's `Flash`
/// (which counts from the start of flash).
pub const LAYOUT: Layout = Layout {
    slot_offset: [
        slots::TABLE_A - slots::FLASH_BASE,
        slots::TABLE_B - slots::FLASH_BASE,
    ],
    slot_bytes: slots::SLOT_BYTES,
};

/// The internal flash for the table store: embassy-stm32's blocking
/// `Flash`, declared `MultiwriteNorFlash` — the STM32F4 programs zeros over
/// programmed bits (no ECC, no "not erased" error; ST's AN3969 EEPROM
/// emulation for the F40x relies on it), which the store's rollback uses
/// to zero a revoked slot's header magic (trueaxis_app::store).
pub struct TableFlash(pub Flash<'static, Blocking>);

impl embedded_storage::nor_flash::ErrorType for TableFlash {
    type Error = embassy_stm32::flash::Error;
}

impl embedded_storage::nor_flash::ReadNorFlash for TableFlash {
    const READ_SIZE: usize =
        <Flash<'static, Blocking> as embedded_storage::nor_flash::ReadNorFlash>::READ_SIZE;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        embedded_storage::nor_flash::ReadNorFlash::read(&mut self.0, offset, bytes)
    }

    fn capacity(&self) -> usize {
        embedded_storage::nor_flash::ReadNorFlash::capacity(&self.0)
    }
}

impl embedded_storage::nor_flash::NorFlash for TableFlash {
    const WRITE_SIZE: usize =
        <Flash<'static, Blocking> as embedded_storage::nor_flash::NorFlash>::WRITE_SIZE;
    const ERASE_SIZE: usize =
        <Flash<'static, Blocking> as embedded_storage::nor_flash::NorFlash>::ERASE_SIZE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        embedded_storage::nor_flash::NorFlash::erase(&mut self.0, from, to)
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        embedded_storage::nor_flash::NorFlash::write(&mut self.0, offset, bytes)
    }
}

impl embedded_storage::nor_flash::MultiwriteNorFlash for TableFlash {}

/// Correction loop rate (defined in model-core, which derives the loop's
/// instruction budget from it).
pub const LOOP_HZ: u64 = model_core::board::LOOP_HZ as u64;

/// The machine this board is set up for: 0.1 µm glass scales read in
/// quadrature (25 nm/count… expressed as 25 000 pm), 100 nm correction
/// steps at the drives, 500 mm/s rapid traverse, four thermistors.
///
/// `max_steps_per_tick = 2` bounds the bit-banged pulses to 2 × 2 µs per
/// axis and tick (12 µs of the 50 µs period for three axes); one pulse per
/// tick is 2 mm/s of correction slew, well above any table's limit and the
/// 1 mm/s fault ramp.
pub const ENGINE: EngineConfig = EngineConfig {
    axes: [AXIS; 3],
    period_us: (1_000_000 / LOOP_HZ) as u32,
    max_steps_per_tick: 2,
    temps_used: 4,
    temp_min_mc: -20_000,
    temp_max_mc: 80_000,
    fault_ramp_nm_per_ms: 1_000,
    tool_nm: 0,
};

const AXIS: AxisConfig = AxisConfig {
    pm_per_count: 25_000,
    origin_nm: 0,
    pulse_nm: 100,
    max_speed_nm_per_ms: 500_000,
    // TIM2-TIM4 in encoder mode, read as 16 bits and widened (`Widen16`):
    // at 500 mm/s and 25 nm per count the widening follows the axis over
    // gaps up to 1.638 ms between ticks; an axis that moves across a
    // longer gap (a stall) loses its reference.
    counter_bits: 16,
    home: Some(HOME),
};

/// The home switches (PC8-PC10) trip at the machine's origin, approached
/// moving towards negative counts (homing to the minimum end); a build
/// for a machine whose switches sit elsewhere sets that here. Debounced
/// over 4 ticks (200 µs; the edge is dated at the first of them, so the
/// debounce costs no accuracy). A referenced axis whose switch turns on
/// more than 100 µm from 0 — a glitch on the input, or a position that
/// drifted — faults (`home_mismatch`) and loses its reference: 100 µm is
/// a mechanical switch's repeatability with margin plus the 25 µm a
/// 500 mm/s pass moves in the one tick the input is read late.
const HOME: HomeSwitch = HomeSwitch {
    pos_nm: 0,
    approach: Approach::Negative,
    debounce_ticks: 4,
    tolerance_nm: 100_000,
};

/// Thermistors fitted on PC0-PC3.
pub const NTC: Ntc = Ntc::NTC_10K_3950;

/// Independent watchdog timeout, µs. It must cover a flash sector erase
/// (128 KiB: 1-2 s typical at x32 parallelism, during which nothing runs)
/// with margin; the watchdog task pets it every 250 ms while the loop runs.
pub const WATCHDOG_US: u32 = 4_000_000;

/// Clocks: 8 MHz crystal → PLL → 168 MHz core, 48 MHz USB; APB1 42 MHz
/// (timers 84 MHz), APB2 84 MHz.
pub fn clocks() -> embassy_stm32::Config {
    use embassy_stm32::rcc::*;
    let mut config = embassy_stm32::Config::default();
    config.rcc.hse = Some(Hse {
        freq: Hertz(8_000_000),
        mode: HseMode::Oscillator,
    });
    config.rcc.pll_src = PllSource::HSE;
    config.rcc.pll = Some(Pll {
        prediv: PllPreDiv::DIV4,
        mul: PllMul::MUL168,
        divp: Some(PllPDiv::DIV2), // 8 / 4 · 168 / 2 = 168 MHz
        divq: Some(PllQDiv::DIV7), // 8 / 4 · 168 / 7 = 48 MHz
        divr: None,
    });
    config.rcc.ahb_pre = AHBPrescaler::DIV1;
    config.rcc.apb1_pre = APBPrescaler::DIV4;
    config.rcc.apb2_pre = APBPrescaler::DIV2;
    config.rcc.sys = Sysclk::PLL1_P;
    config.rcc.mux.clk48sel = mux::Clk48sel::PLL1_Q;
    config
}

/// The high-priority executor the correction loop runs on.
static EXECUTOR_HIGH: InterruptExecutor = InterruptExecutor::new();

// The executor's software interrupt. UART4 is not used by the board.
#[allow(unsafe_code)]
#[irq_attr]
unsafe fn UART4() {
    // SAFETY: the executor was started on this interrupt (start_high) and
    // this is its only handler.
    unsafe { EXECUTOR_HIGH.on_interrupt() }
}

/// Starts the correction executor on UART4 at priority P6. On Cortex-M a
/// lower number is a higher priority: P6 preempts thread mode (the link,
/// thermistor and watchdog tasks) and the USB/USART interrupts, which
/// [`take`] moves down to P7. Only the time driver's TIM5 interrupt (which
/// wakes the loop) stays above it.
pub fn start_high() -> SendSpawner {
    interrupt::UART4.set_priority(Priority::P6);
    EXECUTOR_HIGH.start(interrupt::UART4)
}

/// The three encoders (TIM2/3/4 in encoder mode), widened to 32 bits, and
/// the axes' home switches.
pub struct BoardEncoders {
    x: Qei<'static, TIM2>,
    y: Qei<'static, TIM3>,
    z: Qei<'static, TIM4>,
    wide: [Widen16; 3],
    /// Home switches X, Y, Z: active low (a switch to ground, pull-up on),
    /// so an unwired input never references an axis.
    home: [Input<'static>; 3],
}

impl Encoders for BoardEncoders {
    fn read_counts(&mut self) -> [i32; 3] {
        let raw = [self.x.count(), self.y.count(), self.z.count()];
        core::array::from_fn(|i| self.wide[i].update(raw[i]))
    }

    fn home_switches(&mut self) -> u8 {
        self.home
            .iter()
            .enumerate()
            .fold(0, |m, (i, pin)| m | (u8::from(pin.is_low()) << i))
    }
}

/// Step/direction outputs, bit-banged: 1 µs high, 1 µs low.
pub struct StepDir {
    step: [Output<'static>; 3],
    dir: [Output<'static>; 3],
}

impl StepOutput for StepDir {
    fn pulses(&mut self, axis: usize, steps: i32) {
        let (Some(step), Some(dir)) = (self.step.get_mut(axis), self.dir.get_mut(axis)) else {
            return;
        };
        dir.set_level(if steps >= 0 { Level::High } else { Level::Low });
        for _ in 0..steps.unsigned_abs() {
            step.set_high();
            cortex_m::asm::delay(168); // 1 µs at 168 MHz
            step.set_low();
            cortex_m::asm::delay(168);
        }
    }
}

/// The four thermistor inputs on ADC1.
pub struct Thermistors {
    adc: Adc<'static, ADC1>,
    pins: (
        Peri<'static, PC0>,
        Peri<'static, PC1>,
        Peri<'static, PC2>,
        Peri<'static, PC3>,
    ),
}

impl Thermistors {
    /// Raw 12-bit readings of channels 0-3 (480-cycle sampling: the
    /// divider's 5 kΩ source impedance needs a long sample time).
    pub fn read_raw(&mut self) -> [u16; 4] {
        let t = SampleTime::CYCLES480;
        [
            self.adc.blocking_read(&mut self.pins.0, t),
            self.adc.blocking_read(&mut self.pins.1, t),
            self.adc.blocking_read(&mut self.pins.2, t),
            self.adc.blocking_read(&mut self.pins.3, t),
        ]
    }
}

/// USB OTG FS driver type.
pub type UsbDriver = usb::Driver<'static, USB_OTG_FS>;

/// What the tasks get.
pub struct Parts {
    /// Encoders (correction loop).
    pub encoders: BoardEncoders,
    /// Step/dir outputs (correction loop).
    pub steps: StepDir,
    /// Thermistors (thermistor task).
    pub thermistors: Thermistors,
    /// USB driver (USB tasks).
    pub usb: UsbDriver,
    /// USART1 link (UART link task).
    pub uart: BufferedUart<'static>,
    /// Internal flash (table store).
    pub flash: TableFlash,
    /// Watchdog, not started yet.
    pub iwdg: IndependentWatchdog<'static, IWDG>,
}

/// Takes the peripherals apart for the tasks.
pub fn take(p: Peripherals) -> Parts {
    static USB_EP_OUT: StaticCell<[u8; 256]> = StaticCell::new();
    static UART_TX: StaticCell<[u8; 512]> = StaticCell::new();
    static UART_RX: StaticCell<[u8; 512]> = StaticCell::new();

    let qei = QeiConfig {
        ch1_pull: Pull::Up,
        ch2_pull: Pull::Up,
        ..QeiConfig::default()
    };
    let encoders = BoardEncoders {
        x: Qei::new(p.TIM2, p.PA15, p.PB3, qei),
        y: Qei::new(p.TIM3, p.PA6, p.PA7, qei),
        z: Qei::new(p.TIM4, p.PB6, p.PB7, qei),
        wide: [Widen16::new(0); 3],
        home: [
            Input::new(p.PC8, Pull::Up),
            Input::new(p.PC9, Pull::Up),
            Input::new(p.PC10, Pull::Up),
        ],
    };
    let out = |pin: Peri<'static, AnyPin>| Output::new(pin, Level::Low, Speed::VeryHigh);
    let steps = StepDir {
        step: [out(p.PB12.into()), out(p.PB14.into()), out(p.PC6.into())],
        dir: [out(p.PB13.into()), out(p.PB15.into()), out(p.PC7.into())],
    };
    let thermistors = Thermistors {
        adc: Adc::new(p.ADC1),
        pins: (p.PC0, p.PC1, p.PC2, p.PC3),
    };

    let mut usb_config = usb::Config::default();
    // Bus-powered from the machine's 24 V, not from USB: no VBUS sensing
    // (PA9 is the UART's TX).
    usb_config.vbus_detection = false;
    let usb = usb::Driver::new_fs(
        p.USB_OTG_FS,
        Irqs,
        p.PA12,
        p.PA11,
        USB_EP_OUT.init([0; 256]),
        usb_config,
    );

    let mut uart_config = usart::Config::default();
    uart_config.baudrate = 115_200;
    let uart = match BufferedUart::new(
        p.USART1,
        p.PA10,
        p.PA9,
        UART_TX.init([0; 512]),
        UART_RX.init([0; 512]),
        Irqs,
        uart_config,
    ) {
        Ok(u) => u,
        // A fixed, valid configuration: cannot fail at run time.
        Err(_) => defmt::panic!("USART1 configuration"),
    };

    // The link interrupts below the correction executor (P6).
    interrupt::OTG_FS.set_priority(Priority::P7);
    interrupt::USART1.set_priority(Priority::P7);

    Parts {
        encoders,
        steps,
        thermistors,
        usb,
        uart,
        flash: TableFlash(Flash::new_blocking(p.FLASH)),
        iwdg: IndependentWatchdog::new(p.IWDG, WATCHDOG_US),
    }
}
