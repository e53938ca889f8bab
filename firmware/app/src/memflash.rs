//! A RAM-backed NOR flash (embassy's `MemFlash` idea) that behaves like the
//! real thing where the table store depends on it, and can lose power.
//!
//! - Erase sets whole erase units to `0xFF`; a write may only program
//!   erased bytes (the STM32F4 flags a programming error otherwise), and
//!   both must be aligned to `ERASE`/`WRITE` — mistakes the store could
//!   make on hardware fail here too.
//! - A **power cut** after `n` operations: operation `n + 1` is *torn*
//!   (a write programs only its first half, an erase erases only its first
//!   half, the rest keeps its old content, and the caller sees
//!   [`MemFlashError::PowerCut`]) and every later operation fails
//!   with [`MemFlashError::PowerCut`] without touching the contents. The
//!   power-cut tests run a commit with `n = 0, 1, 2, …` until it completes,
//!   "reboot" on what is left, and check that a valid table is active.
//!
//! Generic over the buffer (`Vec<u8>` in host tests, a `&mut [u8]` or an
//! array in QEMU images), no allocation, no `unsafe`.

use embedded_storage::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

/// What a [`MemFlash`] operation can fail with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MemFlashError {
    /// Offset or length not aligned to the write or erase size.
    NotAligned,
    /// Past the end of the memory.
    OutOfBounds,
    /// Programming a byte that is not erased.
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

/// RAM-backed NOR flash with write size `WRITE` and erase size `ERASE`.
#[derive(Debug, Clone)]
pub struct MemFlash<B, const WRITE: usize, const ERASE: usize> {
    mem: B,
    ops: usize,
    cut_after: Option<usize>,
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
            cut_after: None,
        }
    }

    /// Wraps `mem` as it is (e.g. the contents left by a power cut).
    pub fn from_contents(mem: B) -> Self {
        Self {
            mem,
            ops: 0,
            cut_after: None,
        }
    }

    /// Cuts the power after `n` more erase/write operations (`None`: never).
    pub fn cut_power_after(&mut self, n: Option<usize>) {
        self.ops = 0;
        self.cut_after = n;
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

    /// Counts one operation; returns whether it runs whole (`Ok(true)`),
    /// torn (`Ok(false)`) or not at all.
    fn begin_op(&mut self) -> Result<bool, MemFlashError> {
        let n = self.ops;
        self.ops += 1;
        match self.cut_after {
            Some(cut) if n > cut => Err(MemFlashError::PowerCut),
            Some(cut) if n == cut => Ok(false),
            _ => Ok(true),
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
        let whole = self.begin_op()?;
        let r = if whole {
            r
        } else {
            r.start..r.start + r.len() / 2
        };
        self.mem.as_mut()[r].fill(0xFF);
        if whole {
            Ok(())
        } else {
            Err(MemFlashError::PowerCut)
        }
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        if !(offset as usize).is_multiple_of(WRITE) || !bytes.len().is_multiple_of(WRITE) {
            return Err(MemFlashError::NotAligned);
        }
        let r = self.range(offset, bytes.len())?;
        if self.mem.as_ref()[r.clone()].iter().any(|&b| b != 0xFF) {
            return Err(MemFlashError::NotErased);
        }
        let whole = self.begin_op()?;
        let n = if whole {
            bytes.len()
        } else {
            (bytes.len() / WRITE / 2) * WRITE
        };
        self.mem.as_mut()[r.start..r.start + n].copy_from_slice(&bytes[..n]);
        if whole {
            Ok(())
        } else {
            Err(MemFlashError::PowerCut)
        }
    }
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
}
