//! The A/B table store: two flash slots (TABLE_A / TABLE_B of `memory.x`),
//! each holding one table with a commit sequence number. Boot uses the
//! valid slot with the highest sequence number.
//!
//! **Slot layout**: `trueaxis_protocol::slot` (header with magic, sequence
//! number, length and CRCs; a revoke marker; the table) — shared with the
//! host's `trueaxis flash`, which writes the same image through a probe.
//!
//! A slot is **valid** when the header's magic and CRC are right, it is not
//! revoked, the table's bytes have the header's CRC and the caller's
//! validation (model-core's full `parse` + `Model::load`) accepts them.
//!
//! **Commit** (to the slot that is *not* active): erase the slot, write the
//! table, read it back, write the header last, read it back. Until the
//! header is complete the slot is invalid (wrong magic, or a header CRC
//! that does not match a half-written header), so the active slot stays
//! the newest valid one whatever step a power cut interrupts; after it the
//! new slot has a higher sequence number and wins. The active slot is never
//! erased or written by a commit.
//!
//! **Rollback** programs the active slot's revoke marker to zero, then
//! zeroes its header's magic word: two writes that need no erase, the
//! second over programmed bits, which is why rollback needs a
//! `MultiwriteNorFlash` (the STM32F4 clears bits over programmed ones: no
//! ECC; ST's AN3969 EEPROM emulation relies on it; the board wraps
//! embassy-stm32's `Flash` to say so). After either write the other slot
//! is the newest valid one; torn, each leaves a state that names a valid
//! table (a marker with any bit cleared is "revoked", a magic with any bit
//! cleared is no header). It is refused unless the other slot holds a
//! valid table.
//!
//! **The revoked slot and a torn erase.** After a rollback the revoked slot
//! has the *higher* sequence number, and it is the next commit's target.
//! A power cut during that commit's erase can leave any mix of erased and
//! old bits (the F405's sector erase is one step whose order is not
//! documented). Had the rollback only revoked, an erase torn so that the
//! revoke marker came back to all-ones while header and table survived
//! would resurrect the rolled-back table. With the magic zeroed too, the
//! header is dead unless the erase brought back exactly the magic's bits
//! and none of the others that the header CRC covers — and a header that
//! comes back whole also needs the table's CRC to match. Tested with the
//! worst order (the marker erased first, nothing else) and with seeded
//! mixes.
//!
//! These claims are tested by cutting the power at every erase and write
//! step — and every word of every write — of commits and rollbacks against
//! [`MemFlash`](crate::memflash), with model-core's parse + load as the
//! validator and the F405's 128 KiB sectors (app/tests/store_power_cut.rs).

use embedded_storage::nor_flash::{MultiwriteNorFlash, NorFlash, ReadNorFlash};
use trueaxis_protocol::slot::{
    decode_header, encode_header, is_live, BODY_AT, HEADER_AT, HEADER_BYTES, REVOKE_AT,
    REVOKE_BYTES,
};
use trueaxis_protocol::{table_id, Slot, SlotInfo};

/// Bytes written or compared per flash operation.
const CHUNK: usize = 256;

/// Where the two slots are, as offsets for the `NorFlash` (for
/// embassy-stm32's `Flash` these are offsets from the start of flash:
/// TABLE_A = 0x080C_0000 → 0xC_0000).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Layout {
    /// Offset of slot A and slot B.
    pub slot_offset: [u32; 2],
    /// Size of each slot, bytes (a multiple of the erase size).
    pub slot_bytes: u32,
}

impl Layout {
    /// Largest table a slot can hold, bytes.
    pub const fn max_table_bytes(&self) -> u32 {
        self.slot_bytes - BODY_AT
    }
}

/// What a store operation can fail with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StoreError {
    /// Slots not aligned to the flash's erase/write sizes, overlapping or
    /// outside the flash.
    BadLayout,
    /// Erase, write or read failed.
    Flash,
    /// Read-back differs from what was written.
    Verify,
    /// The table is larger than a slot (or the caller's buffer).
    TooLarge,
    /// The validation refused the table.
    InvalidTable,
    /// Rollback without a valid table in the other slot.
    NothingToRollBackTo,
    /// No valid slot.
    Empty,
}

fn slot_index(s: Slot) -> usize {
    match s {
        Slot::A => 0,
        Slot::B => 1,
    }
}

const SLOTS: [Slot; 2] = [Slot::A, Slot::B];

/// The store over a NOR flash `F`.
#[derive(Debug)]
pub struct TableStore<F> {
    flash: F,
    layout: Layout,
    /// What a scan (kept up to date by commit and rollback) found valid.
    valid: [Option<SlotInfo>; 2],
}

impl<F: NorFlash + ReadNorFlash> TableStore<F> {
    /// A store over `flash`; call [`scan`](Self::scan) before use.
    pub fn new(flash: F, layout: Layout) -> Result<Self, StoreError> {
        let e = F::ERASE_SIZE as u32;
        let w = F::WRITE_SIZE as u32;
        let cap = flash.capacity() as u64;
        let ok = w > 0
            && (HEADER_BYTES as u32).is_multiple_of(w)
            && (CHUNK as u32).is_multiple_of(w)
            && layout.slot_bytes > BODY_AT
            && layout.slot_bytes.is_multiple_of(e)
            && layout
                .slot_offset
                .iter()
                .all(|&o| o.is_multiple_of(e) && o as u64 + layout.slot_bytes as u64 <= cap)
            && layout.slot_offset[0].abs_diff(layout.slot_offset[1]) >= layout.slot_bytes;
        if !ok {
            return Err(StoreError::BadLayout);
        }
        Ok(Self {
            flash,
            layout,
            valid: [None, None],
        })
    }

    /// The layout.
    pub fn layout(&self) -> Layout {
        self.layout
    }

    /// The flash (tests look at its contents).
    pub fn flash(&self) -> &F {
        &self.flash
    }

    /// Gives the flash back.
    pub fn into_flash(self) -> F {
        self.flash
    }

    /// Reads both slots and validates them; `buf` must hold the largest
    /// table expected (a larger one makes its slot invalid), `validate`
    /// is the full model-core check.
    pub fn scan(&mut self, buf: &mut [u8], mut validate: impl FnMut(&[u8]) -> bool) {
        for (i, slot) in SLOTS.into_iter().enumerate() {
            self.valid[i] = self.check_slot(slot, buf, &mut validate);
        }
    }

    fn check_slot(
        &mut self,
        slot: Slot,
        buf: &mut [u8],
        validate: &mut impl FnMut(&[u8]) -> bool,
    ) -> Option<SlotInfo> {
        let base = self.layout.slot_offset[slot_index(slot)];
        let mut h = [0u8; HEADER_BYTES];
        self.flash.read(base + HEADER_AT, &mut h).ok()?;
        let info = decode_header(&h, slot)?;
        if info.len > self.layout.max_table_bytes() || info.len as usize > buf.len() {
            return None;
        }
        let mut r = [0u8; REVOKE_BYTES];
        self.flash.read(base + REVOKE_AT, &mut r).ok()?;
        if !is_live(&r) {
            return None;
        }
        let body = &mut buf[..info.len as usize];
        self.flash.read(base + BODY_AT, body).ok()?;
        if table_id(body) != info.crc32 || !validate(body) {
            return None;
        }
        Some(info)
    }

    /// What the last scan, commit or rollback left valid, per slot (A, B).
    pub fn valid_slots(&self) -> [Option<SlotInfo>; 2] {
        self.valid
    }

    /// The newest valid table (the one boot uses).
    pub fn active(&self) -> Option<SlotInfo> {
        match self.valid {
            [Some(a), Some(b)] => Some(if b.seq > a.seq { b } else { a }),
            [a, b] => a.or(b),
        }
    }

    /// The other valid table, if any (the rollback target).
    pub fn standby(&self) -> Option<SlotInfo> {
        let active = self.active()?;
        self.valid[1 - slot_index(active.slot)]
    }

    /// Reads the table of `info` into `buf` and returns it (CRC checked).
    pub fn read_table<'b>(
        &mut self,
        info: SlotInfo,
        buf: &'b mut [u8],
    ) -> Result<&'b [u8], StoreError> {
        let body = buf
            .get_mut(..info.len as usize)
            .ok_or(StoreError::TooLarge)?;
        let base = self.layout.slot_offset[slot_index(info.slot)];
        self.flash
            .read(base + BODY_AT, body)
            .map_err(|_| StoreError::Flash)?;
        if table_id(body) != info.crc32 {
            return Err(StoreError::Verify);
        }
        Ok(body)
    }

    /// Writes `table` (validated by `validate` first) to the slot that is
    /// not active, with the next sequence number, and verifies it. On
    /// success it is the newest valid table.
    pub fn commit(
        &mut self,
        table: &[u8],
        validate: impl FnOnce(&[u8]) -> bool,
    ) -> Result<SlotInfo, StoreError> {
        if table.len() > self.layout.max_table_bytes() as usize {
            return Err(StoreError::TooLarge);
        }
        if !validate(table) {
            return Err(StoreError::InvalidTable);
        }
        let active = self.active();
        let target = match active {
            Some(a) if a.slot == Slot::A => Slot::B,
            _ => Slot::A,
        };
        let info = SlotInfo {
            slot: target,
            seq: active.map_or(1, |a| a.seq.wrapping_add(1)),
            len: table.len() as u32,
            crc32: table_id(table),
        };
        let ti = slot_index(target);
        self.valid[ti] = None;
        let base = self.layout.slot_offset[ti];

        // 1. Erase, unit by unit (a cut may land between any two).
        let e = F::ERASE_SIZE as u32;
        let mut at = base;
        while at < base + self.layout.slot_bytes {
            self.flash
                .erase(at, at + e)
                .map_err(|_| StoreError::Flash)?;
            at += e;
        }
        // 2. The table, padded to the write size with erased bytes.
        let w = F::WRITE_SIZE;
        let mut off = 0usize;
        for chunk in table.chunks(CHUNK) {
            let mut tmp = [0xFFu8; CHUNK];
            tmp[..chunk.len()].copy_from_slice(chunk);
            let n = chunk.len().div_ceil(w) * w;
            self.flash
                .write(base + BODY_AT + off as u32, &tmp[..n])
                .map_err(|_| StoreError::Flash)?;
            off += chunk.len();
        }
        // 3. Read it back.
        for (k, chunk) in table.chunks(CHUNK).enumerate() {
            let mut tmp = [0u8; CHUNK];
            let got = &mut tmp[..chunk.len()];
            self.flash
                .read(base + BODY_AT + (k * CHUNK) as u32, got)
                .map_err(|_| StoreError::Flash)?;
            if got != chunk {
                return Err(StoreError::Verify);
            }
        }
        // 4. The header last: only now can the slot become valid.
        let h = encode_header(&info);
        self.flash
            .write(base + HEADER_AT, &h)
            .map_err(|_| StoreError::Flash)?;
        let mut back = [0u8; HEADER_BYTES];
        self.flash
            .read(base + HEADER_AT, &mut back)
            .map_err(|_| StoreError::Flash)?;
        if back != h {
            return Err(StoreError::Verify);
        }
        self.valid[ti] = Some(info);
        Ok(info)
    }
}

impl<F: MultiwriteNorFlash + ReadNorFlash> TableStore<F> {
    /// Revokes the active table (marker, then the header's magic: see the
    /// module documentation); the other slot's becomes active and is
    /// returned.
    pub fn rollback(&mut self) -> Result<SlotInfo, StoreError> {
        let active = self.active().ok_or(StoreError::Empty)?;
        let standby = self.standby().ok_or(StoreError::NothingToRollBackTo)?;
        let ai = slot_index(active.slot);
        let base = self.layout.slot_offset[ai];
        self.flash
            .write(base + REVOKE_AT, &[0u8; REVOKE_BYTES])
            .map_err(|_| StoreError::Flash)?;
        self.valid[ai] = None;
        // The magic word (one write unit; `new` checked it fits the header).
        let zeros = [0u8; HEADER_BYTES];
        self.flash
            .write(base + HEADER_AT, &zeros[..F::WRITE_SIZE.max(4)])
            .map_err(|_| StoreError::Flash)?;
        Ok(standby)
    }
}
