//! Sensor conversions the board needs and that are worth testing on the
//! host: widening 16-bit encoder timers to 32-bit counts, and thermistor
//! ADC readings to m°C.

/// Extends a 16-bit hardware counter (an STM32 timer in encoder mode) to a
/// 32-bit count: each read adds the signed 16-bit difference to the last
/// one. Correct as long as the counter moves less than 32 768 counts
/// between two reads — at a 20 kHz loop that is 655 M counts/s, far beyond
/// any machine axis.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Widen16 {
    last: u16,
    count: i32,
}

impl Widen16 {
    /// Starts at count 0 with the counter reading `raw`.
    pub const fn new(raw: u16) -> Self {
        Self {
            last: raw,
            count: 0,
        }
    }

    /// Feeds a new raw reading; returns the widened count.
    pub fn update(&mut self, raw: u16) -> i32 {
        let d = raw.wrapping_sub(self.last) as i16;
        self.last = raw;
        self.count = self.count.wrapping_add(d as i32);
        self.count
    }
}

/// An NTC thermistor on a divider: `pullup_ohm` from the reference to the
/// ADC pin, the thermistor from the pin to ground.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Ntc {
    /// Resistance at 25 °C, Ω.
    pub r25_ohm: f32,
    /// β constant, K.
    pub beta_k: f32,
    /// Divider pull-up, Ω.
    pub pullup_ohm: f32,
    /// ADC full scale (4095 for 12 bits).
    pub full_scale: u16,
}

impl Ntc {
    /// A 10 kΩ, β = 3950 K thermistor with a 10 kΩ pull-up on a 12-bit ADC.
    pub const NTC_10K_3950: Ntc = Ntc {
        r25_ohm: 10_000.0,
        beta_k: 3950.0,
        pullup_ohm: 10_000.0,
        full_scale: 4095,
    };

    /// Temperature in m°C for an ADC reading (β equation). A reading at
    /// either rail (open or shorted sensor) returns `i32::MIN`, which any
    /// plausible range rejects: the engine reports `SENSOR_RANGE`.
    pub fn temp_mc(&self, raw: u16) -> i32 {
        if raw == 0 || raw >= self.full_scale {
            return i32::MIN;
        }
        let r = self.pullup_ohm * raw as f32 / (self.full_scale - raw) as f32;
        let inv_t = 1.0 / 298.15 + libm::logf(r / self.r25_ohm) / self.beta_k;
        let t_c = 1.0 / inv_t - 273.15;
        if !t_c.is_finite() {
            return i32::MIN;
        }
        (t_c * 1000.0) as i32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn widening_follows_wraps_both_ways() {
        let mut w = Widen16::new(65_530);
        assert_eq!(w.update(65_535), 5);
        assert_eq!(w.update(10), 16);
        assert_eq!(w.update(65_000), 16 - 546);
        // A long run forward: 10 full turns of the 16-bit counter.
        let mut raw = 65_000u16;
        let mut w = Widen16::new(raw);
        for _ in 0..(10 * 65_536 / 1000) {
            raw = raw.wrapping_add(1000);
            w.update(raw);
        }
        assert_eq!(w.update(raw), (10 * 65_536 / 1000) * 1000);
    }

    #[test]
    fn ntc_reads_25c_at_mid_scale_and_rails_are_faults() {
        let n = Ntc::NTC_10K_3950;
        // R = pull-up at mid scale: 25 °C.
        let t = n.temp_mc(2048);
        assert!((t - 25_000).abs() < 50, "{t}");
        // Hotter = lower resistance = lower reading.
        assert!(n.temp_mc(1000) > n.temp_mc(3000));
        // 10 kΩ β3950 at 50 °C is 3.588 kΩ: reading 4095·3588/13588.
        let t50 = n.temp_mc((4095.0 * 3588.0 / 13588.0) as u16);
        assert!((t50 - 50_000).abs() < 300, "{t50}");
        assert_eq!(n.temp_mc(0), i32::MIN);
        assert_eq!(n.temp_mc(4095), i32::MIN);
    }
}
