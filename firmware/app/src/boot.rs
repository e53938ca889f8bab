//! Boot fallback (the embassy-boot habit of a confirm window): a board that
//! boots a table which crashes it returns to the previous table by itself.
//!
//! **Trial.** Whenever a table starts running — at boot, after a commit,
//! after a rollback — it is *on trial* until the correction loop has run
//! [`CONFIRM_MS`] on it (counted in engine ticks, like the injection lease,
//! so it means the same under an emulator). Then it is *confirmed*. If a
//! fault resets the board while the table is on trial — a panic, a
//! HardFault, or the watchdog (the loop stopped) — the next boot revokes
//! that table (the rollback's one-word revoke marker, so it stays revoked
//! after a power cycle too), activates the other slot and latches
//! [`Faults::TRIAL_FAILED`] with the `RESET_BY_*` bit that says which
//! fault: `trueaxis status` shows both. With no other valid table the boot
//! runs none (the correction stays at zero, `NO_TABLE`) instead of a table
//! that crashed the board: a reset loop is what bricks a board.
//!
//! **Where the trial state lives: RAM that survives a reset**, a
//! [`BootRecord`] of [`RECORD_WORDS`] words in a `.uninit` section with a
//! magic and a check word, written by the server and by the panic and
//! HardFault handlers, read by the next boot. Why not a flash word: every
//! boot would then program flash (a confirm word per boot, an erase to
//! clear it), each program stalls the single-bank F405 with the machine
//! possibly moving, and a power cut during the window would look like a
//! failed trial and throw a good table away. SRAM keeps its contents
//! through a system, watchdog or pin reset (measured in QEMU as well: see
//! docs/firmware.md), and loses them in a power cut — which is not
//! evidence against the table: the boot after a power-up (reported by the
//! board's reset flags, or a record without its magic) starts a new trial
//! of the newest table, and if that table crashes it is caught then. Flash
//! is written only once a trial has failed (the revoke).
//!
//! A reset with no fault recorded (the reset pin, a debugger, a firmware
//! update) does not count against the table: its trial starts again.

use trueaxis_protocol::{Faults, Slot, SlotInfo};

/// How long a table must run without a fault reset to be confirmed, ms.
pub const CONFIRM_MS: u32 = 5000;

/// Words of a [`BootRecord`] in RAM.
pub const RECORD_WORDS: usize = 8;

/// First word of a written record ("TA boot").
const MAGIC: u32 = 0x7A0B_0075;

/// The fault a handler recorded just before it reset the board.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Fault {
    /// A panic (the panic handler resets).
    Panic,
    /// A HardFault (its handler resets).
    HardFault,
    /// The independent watchdog (read from the reset flags at boot).
    Watchdog,
}

impl Fault {
    /// The latched bit that names it.
    pub const fn bit(self) -> Faults {
        match self {
            Fault::Panic => Faults::RESET_BY_PANIC,
            Fault::HardFault => Faults::RESET_BY_HARDFAULT,
            Fault::Watchdog => Faults::RESET_BY_WATCHDOG,
        }
    }

    fn code(self) -> u32 {
        match self {
            Fault::Panic => 1,
            Fault::HardFault => 2,
            Fault::Watchdog => 3,
        }
    }

    fn from_code(c: u32) -> Option<Option<Self>> {
        Some(match c {
            0 => None,
            1 => Some(Fault::Panic),
            2 => Some(Fault::HardFault),
            3 => Some(Fault::Watchdog),
            _ => return None,
        })
    }
}

/// Why the board (re)started, from its reset flags (RCC_CSR on the F405).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ResetCause {
    /// Power-on or brown-out: RAM holds nothing from before.
    PowerOn,
    /// The independent watchdog.
    Watchdog,
    /// Any other reset (software, pin, low-power): RAM kept its contents.
    Other,
}

/// The trial state kept across a reset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BootRecord {
    /// The table running (on trial or confirmed); `None`: none.
    pub table: Option<SlotInfo>,
    /// It ran [`CONFIRM_MS`] without a fault reset.
    pub confirmed: bool,
    /// The fault a handler recorded before resetting, if any.
    pub fault: Option<Fault>,
}

impl BootRecord {
    /// The record of a table just started (on trial).
    pub const fn trial(table: Option<SlotInfo>) -> Self {
        Self {
            table,
            confirmed: false,
            fault: None,
        }
    }

    /// The words to keep in RAM.
    pub fn encode(&self) -> [u32; RECORD_WORDS] {
        let (slot, seq, len, crc) = match self.table {
            None => (0, 0, 0, 0),
            Some(t) => (
                match t.slot {
                    Slot::A => 1,
                    Slot::B => 2,
                },
                t.seq,
                t.len,
                t.crc32,
            ),
        };
        let mut w = [
            MAGIC,
            slot,
            seq,
            len,
            crc,
            u32::from(self.confirmed),
            self.fault.map_or(0, Fault::code),
            0,
        ];
        w[RECORD_WORDS - 1] = check(&w);
        w
    }

    /// The record in `w`, or `None` when `w` is not one (RAM after a power
    /// cut holds anything).
    pub fn decode(w: &[u32; RECORD_WORDS]) -> Option<Self> {
        if w[0] != MAGIC || w[RECORD_WORDS - 1] != check(w) {
            return None;
        }
        let table = match w[1] {
            0 => None,
            s @ (1 | 2) => Some(SlotInfo {
                slot: if s == 1 { Slot::A } else { Slot::B },
                seq: w[2],
                len: w[3],
                crc32: w[4],
            }),
            _ => return None,
        };
        let confirmed = match w[5] {
            0 => false,
            1 => true,
            _ => return None,
        };
        Some(Self {
            table,
            confirmed,
            fault: Fault::from_code(w[6])?,
        })
    }

    /// What a panic or HardFault handler writes before it resets: the
    /// record in `w` with `fault` (left as it is when `w` holds none).
    pub fn record_fault(w: &mut [u32; RECORD_WORDS], fault: Fault) {
        if let Some(mut r) = Self::decode(w) {
            r.fault = Some(fault);
            *w = r.encode();
        }
    }
}

/// Word-wise check: the record's words folded, so that a record whose
/// magic survived a glitch but whose contents did not is refused.
fn check(w: &[u32; RECORD_WORDS]) -> u32 {
    w[..RECORD_WORDS - 1]
        .iter()
        .fold(0x5A5A_A5A5u32, |acc, &x| acc.rotate_left(5) ^ x)
}

/// A trial that failed: the table that was on trial and the fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TrialFailed {
    /// The table that was on trial (the newest stored one).
    pub table: SlotInfo,
    /// The fault that reset the board.
    pub fault: Fault,
}

/// Did the newest table (`newest`, what boot would run) fail its trial?
/// Yes when the record (read from RAM that survived the reset) has it on
/// trial, unconfirmed, and the reset was a fault: one a handler recorded,
/// or the watchdog.
pub fn failed_trial(
    record: Option<BootRecord>,
    reset: ResetCause,
    newest: Option<SlotInfo>,
) -> Option<TrialFailed> {
    if reset == ResetCause::PowerOn {
        return None;
    }
    let r = record?;
    let table = newest?;
    if r.confirmed || r.table != Some(table) {
        return None;
    }
    let fault = match (r.fault, reset) {
        (Some(f), _) => f,
        (None, ResetCause::Watchdog) => Fault::Watchdog,
        (None, _) => return None,
    };
    Some(TrialFailed { table, fault })
}

#[cfg(test)]
mod tests {
    use super::*;

    const T: SlotInfo = SlotInfo {
        slot: Slot::B,
        seq: 7,
        len: 1234,
        crc32: 0xDEAD_BEEF,
    };

    #[test]
    fn a_record_round_trips_and_garbage_is_none() {
        for r in [
            BootRecord::trial(None),
            BootRecord::trial(Some(T)),
            BootRecord {
                table: Some(T),
                confirmed: true,
                fault: Some(Fault::HardFault),
            },
        ] {
            assert_eq!(BootRecord::decode(&r.encode()), Some(r));
        }
        assert_eq!(BootRecord::decode(&[0; RECORD_WORDS]), None);
        let mut w = BootRecord::trial(Some(T)).encode();
        w[2] ^= 1;
        assert_eq!(BootRecord::decode(&w), None);
        // A handler writes nothing over garbage.
        let mut g = [0x1234_5678; RECORD_WORDS];
        BootRecord::record_fault(&mut g, Fault::Panic);
        assert_eq!(g, [0x1234_5678; RECORD_WORDS]);
    }

    #[test]
    fn only_a_fault_during_the_trial_of_the_newest_table_fails_it() {
        let mut w = BootRecord::trial(Some(T)).encode();
        BootRecord::record_fault(&mut w, Fault::Panic);
        let r = BootRecord::decode(&w);
        let failed = Some(TrialFailed {
            table: T,
            fault: Fault::Panic,
        });
        assert_eq!(failed_trial(r, ResetCause::Other, Some(T)), failed);
        // A power cut: RAM is not trusted, the trial starts again.
        assert_eq!(failed_trial(r, ResetCause::PowerOn, Some(T)), None);
        // Another table is the newest (a commit the record never saw).
        let other = SlotInfo { seq: 8, ..T };
        assert_eq!(failed_trial(r, ResetCause::Other, Some(other)), None);
        // Confirmed before the fault: not the table's trial.
        let mut c = r.unwrap();
        c.confirmed = true;
        assert_eq!(failed_trial(Some(c), ResetCause::Other, Some(T)), None);
        // No fault recorded: a reset pin or debugger, not a failure...
        let plain = Some(BootRecord::trial(Some(T)));
        assert_eq!(failed_trial(plain, ResetCause::Other, Some(T)), None);
        // ...unless the watchdog says the loop stopped.
        assert_eq!(
            failed_trial(plain, ResetCause::Watchdog, Some(T)),
            Some(TrialFailed {
                table: T,
                fault: Fault::Watchdog
            })
        );
    }
}
