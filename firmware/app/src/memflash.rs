//! A RAM-backed NOR flash (embassy's `MemFlash` idea) that behaves like the
//! real thing where the table store depends on it, and can lose power.
//!
//! - Erase sets whole erase units to `0xFF`, one operation per unit
//!   (the F405 erases a whole sector in one step); both erase and write
//!   must be aligned to `ERASE`/`WRITE` — mistakes the store could make on
//!   hardware fail here too.
//! - A write can only clear bits: the result is the old contents AND the
//!   data (`MultiwriteNorFlash`, what the STM32F4 does — no ECC, ST's
//!   AN3969 EEPROM emulation programs status words over programmed ones);
//!   a write that would need a 0 bit back to 1 fails with
//!   [`MemFlashError::NotErased`] (the chip would silently keep the 0).
//! - A **power cut** during operation `op` ([`Cut`]): a write is *torn at
//!   a word* — the words before it programmed, that word partly (some of
//!   its bits to be cleared are, chosen by a seed), the rest untouched; an
//!   erase is torn as an arbitrary mix — every bit either its old value or
//!   erased, chosen by the seed (the F405 does not document the order in
//!   which a sector erase proceeds) — or, with [`Cut::ordered_erase`],
//!   a prefix erased (the header first). The cut operation and every later
//!   one fail with [`MemFlashError::PowerCut`], the later ones without
//!   touching the contents. The power-cut tests cut at every operation (and
//!   every word of every write) of a commit, "reboot" on what is left, and
//!   check that a valid table is active.
//!
//! Generic over the buffer (`Vec<u8>` in host tests, a `&mut [u8]` or an
//! array in QEMU images), no allocation, no `unsafe`.

use embedded_storage::nor_flash::{
    ErrorType, MultiwriteNorFlash, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

/// What a [`MemFlash`] operation can fail with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MemFlashError {
    /// Offset or length not aligned to the write or erase size.
    NotAligned,
    /// Past the end of the memory.
    OutOfBounds,
    /// Programming a 1 over a 0 bit (needs an erase first).
    NotErased,
    /// The power is gone.
    PowerCut,
}

impl NorFlashError for MemFlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            MemFlashError::NotAligned => NorFlashErrorKind::NotAligned,
            MemFlashError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            MemFlashError::NotErased | MemFlashError::PowerCut => NorFlashErrorKind::Other,
        }
    }
}

/// Where a power cut lands (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cut {
    /// The operation (counted from 0 since the cut was armed) that is torn.
    pub op: usize,
    /// For a write: the word (of `WRITE` bytes) torn; the ones before it
    /// are programmed. Past the write's end: the whole write done.
    pub word: usize,
    /// Chooses which bits of the torn word, or of the torn erase, changed.
    pub seed: u64,
    /// A torn erase erases a prefix (half the unit) instead of a mix.
    pub ordered_erase: bool,
}

impl Cut {
    /// Operation `op` torn half way (word: half the write; erase: the
    /// first half of the unit), every bit of the torn word kept.
    pub const fn half(op: usize) -> Self {
        Self {
            op,
            word: usize::MAX,
            seed: 0,
            ordered_erase: true,
        }
    }
}

/// RAM-backed NOR flash with write size `WRITE` and erase size `ERASE`.
#[derive(Debug, Clone)]
pub struct MemFlash<B, const WRITE: usize, const ERASE: usize> {
    mem: B,
    ops: usize,
    cut: Option<Cut>,
}

/// xorshift64*: the seeded choice of torn bits (no dependency, no_std).
fn mix(seed: &mut u64) -> u8 {
    *seed ^= *seed << 13;
    *seed ^= *seed >> 7;
    *seed ^= *seed << 17;
    (seed.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 56) as u8
}

impl<B: AsRef<[u8]> + AsMut<[u8]>, const WRITE: usize, const ERASE: usize>
    MemFlash<B, WRITE, ERASE>
{
    /// Wraps `mem`, erasing it.
    pub fn new_erased(mut mem: B) -> Self {
        mem.as_mut().fill(0xFF);
        Self {
            mem,
            ops: 0,
            cut: None,
        }
    }

    /// Wraps `mem` as it is (e.g. the contents left by a power cut).
    pub fn from_contents(mem: B) -> Self {
        Self {
            mem,
            ops: 0,
            cut: None,
        }
    }

    /// Cuts the power after `n` more erase/write operations (`None`: never),
    /// the cut one torn half way ([`Cut::half`]).
    pub fn cut_power_after(&mut self, n: Option<usize>) {
        self.cut_power(n.map(Cut::half));
    }

    /// Cuts the power as `cut` says (`None`: never); operations count from
    /// now.
    pub fn cut_power(&mut self, cut: Option<Cut>) {
        self.ops = 0;
        self.cut = cut;
    }

    /// Erase/write operations since the last `cut_power_after`.
    pub fn ops(&self) -> usize {
        self.ops
    }

    /// The raw contents.
    pub fn contents(&self) -> &[u8] {
        self.mem.as_ref()
    }

    /// The raw contents, mutable (to flip bits in tests).
    pub fn contents_mut(&mut self) -> &mut [u8] {
        self.mem.as_mut()
    }

    /// Gives the buffer back.
    pub fn into_inner(self) -> B {
        self.mem
    }

    /// Counts one operation; returns `None` when it runs whole, the cut
    /// when it is torn, an error when the power is already gone.
    fn begin_op(&mut self) -> Result<Option<Cut>, MemFlashError> {
        let n = self.ops;
        self.ops += 1;
        match self.cut {
            Some(cut) if n > cut.op => Err(MemFlashError::PowerCut),
            Some(cut) if n == cut.op => Ok(Some(cut)),
            _ => Ok(None),
        }
    }

    fn range(&self, offset: u32, len: usize) -> Result<core::ops::Range<usize>, MemFlashError> {
        let start = offset as usize;
        let end = start.checked_add(len).ok_or(MemFlashError::OutOfBounds)?;
        if end > self.mem.as_ref().len() {
            return Err(MemFlashError::OutOfBounds);
        }
        Ok(start..end)
    }
}

impl<B, const WRITE: usize, const ERASE: usize> ErrorType for MemFlash<B, WRITE, ERASE> {
    type Error = MemFlashError;
}

impl<B: AsRef<[u8]> + AsMut<[u8]>, const WRITE: usize, const ERASE: usize> ReadNorFlash
    for MemFlash<B, WRITE, ERASE>
{
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        let r = self.range(offset, bytes.len())?;
        bytes.copy_from_slice(&self.mem.as_ref()[r]);
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.mem.as_ref().len()
    }
}

impl<B: AsRef<[u8]> + AsMut<[u8]>, const WRITE: usize, const ERASE: usize> NorFlash
    for MemFlash<B, WRITE, ERASE>
{
    const WRITE_SIZE: usize = WRITE;
    const ERASE_SIZE: usize = ERASE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        if to < from
            || !(from as usize).is_multiple_of(ERASE)
            || !(to as usize).is_multiple_of(ERASE)
        {
            return Err(MemFlashError::NotAligned);
        }
        let r = self.range(from, (to - from) as usize)?;
        // One operation per erase unit, as the chip erases sector by sector.
        for unit in r.step_by(ERASE) {
            let Some(cut) = self.begin_op()? else {
                self.mem.as_mut()[unit..unit + ERASE].fill(0xFF);
                continue;
            };
            let mem = &mut self.mem.as_mut()[unit..unit + ERASE];
            if cut.ordered_erase {
                mem[..ERASE / 2].fill(0xFF);
            } else {
                let mut seed = cut.seed | 1;
                for b in mem.iter_mut() {
                    *b |= mix(&mut seed);
                }
            }
            return Err(MemFlashError::PowerCut);
        }
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        if !(offset as usize).is_multiple_of(WRITE) || !bytes.len().is_multiple_of(WRITE) {
            return Err(MemFlashError::NotAligned);
        }
        let r = self.range(offset, bytes.len())?;
        let old = &self.mem.as_ref()[r.clone()];
        if old.iter().zip(bytes).any(|(&o, &d)| d & !o != 0) {
            return Err(MemFlashError::NotErased);
        }
        let Some(cut) = self.begin_op()? else {
            for (m, &d) in self.mem.as_mut()[r].iter_mut().zip(bytes) {
                *m &= d;
            }
            return Ok(());
        };
        let words = bytes.len() / WRITE;
        let torn = if cut.word == usize::MAX {
            words / 2
        } else {
            cut.word.min(words)
        };
        let mem = &mut self.mem.as_mut()[r];
        for (m, &d) in mem.iter_mut().zip(bytes).take(torn * WRITE) {
            *m &= d;
        }
        if torn < words && cut.word != usize::MAX {
            // The torn word: each bit to be cleared is, or is not.
            let mut seed = cut.seed | 1;
            let at = torn * WRITE;
            for (m, &d) in mem[at..at + WRITE].iter_mut().zip(&bytes[at..]) {
                *m &= d | mix(&mut seed);
            }
        }
        Err(MemFlashError::PowerCut)
    }
}

impl<B: AsRef<[u8]> + AsMut<[u8]>, const WRITE: usize, const ERASE: usize> MultiwriteNorFlash
    for MemFlash<B, WRITE, ERASE>
{
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nor_rules_and_power_cut() {
        let mut f: MemFlash<Vec<u8>, 4, 64> = MemFlash::new_erased(vec![0; 256]);
        assert_eq!(f.write(1, &[0; 4]), Err(MemFlashError::NotAligned));
        assert_eq!(f.erase(0, 32), Err(MemFlashError::NotAligned));
        assert_eq!(f.write(256, &[0; 4]), Err(MemFlashError::OutOfBounds));
        f.write(0, &[1, 2, 3, 4]).unwrap();
        // Clearing bits again is allowed (F4), setting one is not.
        f.write(0, &[0, 2, 3, 4]).unwrap();
        assert_eq!(f.write(0, &[1, 2, 3, 4]), Err(MemFlashError::NotErased));
        f.cut_power_after(Some(1));
        f.erase(0, 64).unwrap(); // op 0: whole
                                 // Op 1: torn, first 8 bytes only.
        assert_eq!(f.write(0, &[9; 16]), Err(MemFlashError::PowerCut));
        assert_eq!(
            &f.contents()[..16],
            &[9, 9, 9, 9, 9, 9, 9, 9, 255, 255, 255, 255, 255, 255, 255, 255]
        );
        assert_eq!(f.write(16, &[9; 4]), Err(MemFlashError::PowerCut));
        assert_eq!(f.contents()[16], 0xFF);
    }

    #[test]
    fn a_torn_word_clears_some_of_its_bits_a_torn_erase_sets_some() {
        let mut f: MemFlash<Vec<u8>, 4, 64> = MemFlash::new_erased(vec![0; 128]);
        f.cut_power(Some(Cut {
            op: 0,
            word: 1,
            seed: 7,
            ordered_erase: false,
        }));
        assert_eq!(f.write(0, &[0; 16]), Err(MemFlashError::PowerCut));
        let c = f.contents();
        assert_eq!(&c[..4], &[0; 4]);
        assert!(c[4..8].iter().any(|&b| b != 0) && c[4..8].iter().any(|&b| b != 0xFF));
        assert_eq!(&c[8..16], &[0xFF; 8]);
        // Two units: the first erased whole (op 0), the second torn.
        let mut f: MemFlash<Vec<u8>, 4, 64> = MemFlash::from_contents(vec![0; 128]);
        f.cut_power(Some(Cut {
            op: 1,
            word: 0,
            seed: 3,
            ordered_erase: false,
        }));
        assert_eq!(f.erase(0, 128), Err(MemFlashError::PowerCut));
        let c = f.contents();
        assert!(c[..64].iter().all(|&b| b == 0xFF));
        let set: u32 = c[64..].iter().map(|b| b.count_ones()).sum();
        assert!(set > 64 * 2 && set < 64 * 6, "a mix: {set} of 512 bits set");
    }
}
