//! The traits the application core is generic over — the whole of what it
//! needs from hardware. The board implements them with embassy-stm32
//! peripherals (timers in encoder mode, ADC, GPIO, embassy-time), QEMU with
//! its own shims and the host tests with fakes; the core never names a HAL
//! type. Flash is `embedded_storage::nor_flash::NorFlash` (see `store`), the
//! link is plain bytes in and out (see `server`).

use trueaxis_protocol::LINK_TEMPS;

/// Quadrature encoders, one per axis (X, Y, Z).
pub trait Encoders {
    /// Position counts per axis since power-up, extended to 32 bits (the
    /// board widens its 16-bit timers; the engine takes differences with
    /// wrapping arithmetic, so a wrap of the 32-bit count is harmless).
    fn read_counts(&mut self) -> [i32; 3];

    /// Home (reference) switches, one bit per axis (bit 0 = X): set while
    /// the axis is on its switch. The engine references an axis with a
    /// configured `home_nm` when its bit goes from clear to set. Read once
    /// per tick, after `read_counts`. Encoders without switches keep the
    /// default: none.
    fn home_switches(&mut self) -> u8 {
        0
    }
}

/// Temperature sensors.
pub trait TemperatureSource {
    /// Latest temperatures, m°C; channels that are not fitted may read
    /// anything (the engine only checks the first `temps_used`).
    fn read_temps_mc(&mut self) -> [i32; LINK_TEMPS];
}

/// Step/direction outputs to the drive's correction input.
pub trait StepOutput {
    /// Emit `|steps|` pulses on `axis` (0 = X), in the direction of the
    /// sign. Called at most once per axis and tick, with |steps| bounded by
    /// the engine's `max_steps_per_tick`.
    fn pulses(&mut self, axis: usize, steps: i32);
}

/// A monotonic microsecond clock.
pub trait Clock {
    /// Microseconds since an arbitrary origin; never goes backwards.
    fn now_us(&self) -> u64;
}
