//! Fake hardware for the engine tests: encoders, thermistors and a step
//! output in one struct (copied per tick, as the engine reads them), and a
//! clock the test advances.

use std::cell::Cell;

use trueaxis_app::hw::{Clock, Encoders, StepOutput, TemperatureSource};
use trueaxis_protocol::LINK_TEMPS;

/// Encoder counts and temperatures the engine reads, the pulses it emits.
#[derive(Clone, Copy, Debug)]
pub struct Fake {
    /// Encoder counts per axis.
    pub counts: [i32; 3],
    /// Temperatures, m°C.
    pub temps: [i32; LINK_TEMPS],
    /// Net pulses emitted per axis.
    pub pulses: [i64; 3],
    /// Most pulses asked for in one call.
    pub max_pulses_per_call: i32,
    /// Home switches, bit per axis.
    pub home: u8,
}

impl Fake {
    /// At rest at 0, 20 °C everywhere, no pulses.
    pub fn new() -> Self {
        Self {
            counts: [0; 3],
            temps: [20_000; LINK_TEMPS],
            pulses: [0; 3],
            max_pulses_per_call: 0,
            home: 0,
        }
    }
}

impl Encoders for Fake {
    fn read_counts(&mut self) -> [i32; 3] {
        self.counts
    }
    fn home_switches(&mut self) -> u8 {
        self.home
    }
}
impl TemperatureSource for Fake {
    fn read_temps_mc(&mut self) -> [i32; LINK_TEMPS] {
        self.temps
    }
}
impl StepOutput for Fake {
    fn pulses(&mut self, axis: usize, steps: i32) {
        self.pulses[axis] += steps as i64;
        self.max_pulses_per_call = self.max_pulses_per_call.max(steps.abs());
    }
}

/// A clock the test sets, µs.
#[derive(Debug)]
pub struct FakeClock(pub Cell<u64>);
impl Clock for FakeClock {
    fn now_us(&self) -> u64 {
        self.0.get()
    }
}

/// References every axis of `e` at position 0 for the counts its next tick
/// reads (the engine corrects only from referenced axes): with counts 0 and
/// a configured origin 0 the positions are what they were unreferenced.
pub fn reference_at_zero(e: &mut trueaxis_app::engine::Engine<'_>) {
    for axis in 0..3 {
        assert!(e.reference(axis, 0));
    }
}
