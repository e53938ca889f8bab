//! The firmware's application core on the target: the A/B table store on a
//! RAM NOR flash that loses power after every possible erase/write step of
//! a commit, and the correction engine (pulses equal the rounded correction
//! after every tick, output equal to model-core's fixed-point evaluation,
//! slew limit, a fault ramps to zero). The same properties the app's host
//! tests check, here compiled for and run on the Cortex-M4F.
#![no_std]
#![no_main]

#[path = "../src/rig.rs"]
#[allow(dead_code)] // each suite uses part of it
mod rig;

use core::cell::Cell;

use rig::{engine_config, info, FakeClock};
use trueaxis_app::engine::{round_div, Engine, EngineConfig};
use trueaxis_app::hw::{Encoders, StepOutput, TemperatureSource};
use trueaxis_app::memflash::MemFlash;
use trueaxis_app::model::{load_into, ModelBuf};
use trueaxis_app::store::{Layout, TableStore};
use trueaxis_protocol::{table_id, Injection, LINK_TEMPS};
// xorshift64 with a fixed seed.
use trueaxis_test_support::XorShift64 as Rng;

static CUBIC19: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/cubic19.bin"));
static FULL: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/full.bin"));

/// 2 KiB erase units give a commit many cut points.
const ERASE: usize = 2048;
const SLOT: usize = 6 * 1024;
type Flash = MemFlash<&'static mut [u8; 2 * SLOT], 4, ERASE>;
const LAYOUT: Layout = Layout {
    slot_offset: [0, SLOT as u32],
    slot_bytes: SLOT as u32,
};

fn valid(b: &[u8]) -> bool {
    model_core::parse(b).is_ok()
}

/// Boots a store on `mem` (power on) and scans it.
fn boot(mem: &'static mut [u8; 2 * SLOT], buf: &mut [u8]) -> TableStore<Flash> {
    let mut s = match TableStore::new(Flash::from_contents(mem), LAYOUT) {
        Ok(s) => s,
        Err(e) => defmt::panic!("layout refused: {}", e),
    };
    s.scan(buf, valid);
    s
}

/// The CRC of the table the store has active, read back from flash.
fn active_table_crc(s: &mut TableStore<Flash>, buf: &mut [u8]) -> Option<u32> {
    let info = s.active()?;
    match s.read_table(info, buf) {
        Ok(t) => Some(table_id(t)),
        Err(e) => defmt::panic!("active table unreadable: {}", e),
    }
}

/// A table's identity for these tests (model-core's `table_id`).
fn ident(t: &[u8]) -> u32 {
    table_id(t)
}

struct Io {
    counts: [i32; 3],
    temps: [i32; LINK_TEMPS],
    pulses: [i64; 3],
}

impl Encoders for Io {
    fn read_counts(&mut self) -> [i32; 3] {
        self.counts
    }
}
impl TemperatureSource for Io {
    fn read_temps_mc(&mut self) -> [i32; LINK_TEMPS] {
        self.temps
    }
}
struct Pulses<'a>(&'a mut [i64; 3]);
impl StepOutput for Pulses<'_> {
    fn pulses(&mut self, axis: usize, steps: i32) {
        self.0[axis] += i64::from(steps);
    }
}

/// The images' configuration (rig.rs) at 1 kHz with 0.1 µm
/// per count, one thermistor, a 1 µm/ms fault ramp and a 100 mm tool.
fn config() -> EngineConfig {
    let mut c = EngineConfig {
        temps_used: 1,
        fault_ramp_nm_per_ms: 1000,
        tool_nm: 100_000_000,
        ..engine_config(1000)
    };
    for axis in &mut c.axes {
        axis.pm_per_count = 100_000; // 0.1 µm per count
    }
    c
}

/// One tick at the nominal period.
fn tick(e: &mut Engine<'static>, clock: &FakeClock, io: &mut Io) {
    clock.0.set(clock.0.get() + 1000);
    let mut enc = Io { ..*io };
    let mut temps = Io { ..*io };
    e.tick(clock, &mut enc, &mut temps, &mut Pulses(&mut io.pulses));
}

struct State {
    flash: Option<&'static mut [u8; 2 * SLOT]>,
    start: &'static mut [u8; 2 * SLOT],
    buf: &'static mut [u8; SLOT],
    model: Option<&'static mut ModelBuf>,
}

#[defmt_test::tests]
mod tests {
    use super::*;

    #[init]
    fn init() -> State {
        State {
            flash: Some(cortex_m::singleton!(: [u8; 2 * SLOT] = [0xFF; 2 * SLOT]).expect("once")),
            start: cortex_m::singleton!(: [u8; 2 * SLOT] = [0xFF; 2 * SLOT]).expect("once"),
            buf: cortex_m::singleton!(: [u8; SLOT] = [0; SLOT]).expect("once"),
            model: Some(cortex_m::singleton!(: ModelBuf = ModelBuf::new()).expect("once")),
        }
    }

    #[test]
    fn commit_survives_a_power_cut_after_every_flash_step(st: &mut State) {
        let mem = st.flash.take().expect("flash");
        // Start: an erased flash with CUBIC19 committed (slot A).
        mem.fill(0xFF);
        let mut s = boot(mem, st.buf);
        if let Err(e) = s.commit(CUBIC19, valid) {
            defmt::panic!("first commit: {}", e);
        }
        let mem = s.into_flash().into_inner();
        st.start.copy_from_slice(&mem[..]);
        let (old, new) = (ident(CUBIC19), ident(FULL));
        let mut mem = mem;
        let mut cuts = 0u32;
        for n in 0.. {
            mem.copy_from_slice(&st.start[..]);
            let mut s = boot(mem, st.buf);
            let mut f = s.into_flash();
            f.cut_power_after(Some(n));
            s = match TableStore::new(f, LAYOUT) {
                Ok(s) => s,
                Err(e) => defmt::panic!("{}", e),
            };
            s.scan(st.buf, valid);
            let done = s.commit(FULL, valid).is_ok();
            // Power back on: reboot on whatever the flash holds.
            let mut after = boot(s.into_flash().into_inner(), st.buf);
            let got = active_table_crc(&mut after, st.buf);
            if done {
                defmt::assert_eq!(
                    got,
                    Some(new),
                    "complete commit (cut after {}) not active",
                    n
                );
                st.flash = Some(after.into_flash().into_inner());
                break;
            }
            defmt::assert!(
                got == Some(old) || got == Some(new),
                "cut after {} flash operations: the active table is neither the old nor the new one",
                n
            );
            cuts += 1;
            mem = after.into_flash().into_inner();
        }
        defmt::assert!(cuts >= 4, "only {} cut points", cuts);
        defmt::info!(
            "power cut at each of {} steps of a commit: a valid table always active",
            cuts
        );
    }

    #[test]
    fn pulses_equal_the_rounded_correction_after_every_tick(st: &mut State) {
        let model = st.model.take().expect("model buffer");
        if let Err(e) = load_into(FULL, model) {
            defmt::panic!("load: {}", defmt::Debug2Format(&e));
        }
        let mut e = match Engine::new(config()) {
            Ok(e) => e,
            Err(err) => defmt::panic!("config: {}", err),
        };
        let _ = e.set_model(model, info(FULL));
        // The engine corrects only from referenced axes: the counts of the
        // first tick (0.1 µm each) are these positions.
        for (axis, pos_nm) in [400_000_000, 250_000_000, 250_000_000]
            .into_iter()
            .enumerate()
        {
            defmt::assert!(e.reference(axis, pos_nm));
        }
        let clock = FakeClock(Cell::new(0));
        let mut io = Io {
            counts: [4_000_000, 2_500_000, 2_500_000],
            temps: [22_000; LINK_TEMPS],
            pulses: [0; 3],
        };
        let mut rng = Rng(0x1234_5678_9abc_def1);
        let pulse_nm = config().axes.map(|a| i64::from(a.pulse_nm));
        let slew = i64::from(e.slew_nm_per_ms());
        let mut prev = e.corr_nm();
        for k in 0..20_000u32 {
            // Axes wander by up to ±2 µm per ms; temperature drifts.
            for c in io.counts.iter_mut() {
                *c = (i64::from(*c) + rng.range(-20, 20)).clamp(0, 5_000_000) as i32;
            }
            if k % 500 == 0 {
                io.temps[0] = (i64::from(io.temps[0]) + rng.range(-100, 100)) as i32;
            }
            tick(&mut e, &clock, &mut io);
            let corr = e.corr_nm();
            for a in 0..3 {
                let want = round_div(i64::from(corr[a]), pulse_nm[a]);
                defmt::assert_eq!(io.pulses[a], want, "tick {} axis {}: pulses lag", k, a);
                defmt::assert!(
                    i64::from(corr[a] - prev[a]).abs() <= slew + 1,
                    "tick {} axis {}: slew {} > {}",
                    k,
                    a,
                    corr[a] - prev[a],
                    slew
                );
            }
            prev = corr;
        }
        defmt::assert!(e.faults().is_empty(), "faults {}", e.faults().0);
        defmt::assert!(prev.iter().any(|&c| c != 0), "the correction stayed zero");

        // The model's part equals model-core's fixed point on the same inputs.
        let inj = Injection {
            pos_nm: [300_000_000, 200_000_000, 100_000_000],
            rev_q30: [1 << 30, -(1 << 30), 0],
            temp_mc: [23_500, 0, 0, 0, 0, 0, 0, 0],
            tool_nm: 100_000_000,
        };
        let table = model_core::parse(FULL).unwrap_or_else(|_| defmt::panic!("parse"));
        let host = model_core::Model::load(&table).unwrap_or_else(|_| defmt::panic!("load"));
        let want = host.eval_fixed(&model_core::Inputs {
            pos_nm: inj.pos_nm,
            rev_q30: inj.rev_q30,
            temp_mc: [23_500, 0, 0, 0],
            tool_nm: inj.tool_nm,
        });
        let got = e.evaluate_injection(&inj);
        defmt::assert_eq!(got.model_corr_nm, want.corr_nm);

        // A fault (the table goes away) ramps the output to zero, the
        // pulses following, at the fault ramp rate.
        let ramp = i64::from(config().fault_ramp_nm_per_ms);
        let _ = e.clear_model(true);
        let mut prev = e.corr_nm();
        for _ in 0..300 {
            tick(&mut e, &clock, &mut io);
            let now = e.corr_nm();
            for a in 0..3 {
                defmt::assert!(i64::from(now[a] - prev[a]).abs() <= ramp + 1);
                defmt::assert!(now[a].abs() <= prev[a].abs());
            }
            prev = now;
        }
        defmt::assert_eq!(e.corr_nm(), [0; 3]);
        defmt::assert_eq!(io.pulses, [0; 3]);
        defmt::assert!(!e.faults().is_empty());
        defmt::info!(
            "20 000 ticks: pulses == round(corr / pulse) every tick; fault ramped to zero"
        );
    }
}
