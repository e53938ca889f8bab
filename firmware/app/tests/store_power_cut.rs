//! The A/B store against a RAM flash that loses power: for each scenario,
//! cut the power after 0, 1, 2, … erase/write operations until the
//! operation completes uncut, then "reboot" on whatever the flash holds and
//! check that a valid table is active and that it is either the old or the
//! new one — never garbage, never nothing. Also torn operations (the cut
//! operation half done), bit rot in a slot, and the rollback.

use trueaxis_app::memflash::MemFlash;
use trueaxis_app::store::{Layout, StoreError, TableStore};
use trueaxis_protocol::{Slot, SlotInfo};

/// Small erase units (4 KiB, like many NOR chips) give a commit many cut
/// points; the F405's 128 KiB sectors are a special case of this.
type Flash = MemFlash<Vec<u8>, 4, 4096>;

const SLOT: u32 = 16 * 1024;
const LAYOUT: Layout = Layout {
    slot_offset: [0, SLOT],
    slot_bytes: SLOT,
};

/// A "table" for the store's purpose: any bytes the validator accepts.
/// The validator here requires a 4-byte tag, so the test also sees that
/// validation is applied at boot.
fn table(tag: u8, len: usize) -> Vec<u8> {
    let mut v: Vec<u8> = (0..len).map(|i| (i * 7 + tag as usize) as u8).collect();
    v[..4].copy_from_slice(&[b'T', b'B', b'L', tag]);
    v
}

fn valid(b: &[u8]) -> bool {
    b.len() >= 4 && &b[..3] == b"TBL"
}

fn boot(contents: Vec<u8>) -> TableStore<Flash> {
    let mut s = TableStore::new(Flash::from_contents(contents), LAYOUT).unwrap();
    let mut buf = vec![0u8; SLOT as usize];
    s.scan(&mut buf, valid);
    s
}

fn active_table(s: &mut TableStore<Flash>) -> Option<Vec<u8>> {
    let info = s.active()?;
    let mut buf = vec![0u8; SLOT as usize];
    Some(s.read_table(info, &mut buf).unwrap().to_vec())
}

fn fresh() -> TableStore<Flash> {
    let s = TableStore::new(Flash::new_erased(vec![0; 2 * SLOT as usize]), LAYOUT).unwrap();
    boot(s.into_flash().into_inner())
}

/// Runs `op` on a store booted from `start` with the power cut after
/// n = 0, 1, … operations; after each, reboots and checks that the active
/// table is one of `allowed`. Returns how many operations the uncut run
/// took (the first `n` at which it completes: cuts at 0..n-1 all tore it).
fn cut_everywhere(
    start: &[u8],
    allowed: &[Option<Vec<u8>>],
    mut op: impl FnMut(&mut TableStore<Flash>) -> Result<SlotInfo, StoreError>,
) -> usize {
    for n in 0.. {
        let mut s = boot(start.to_vec());
        let mut f = s.into_flash();
        f.cut_power_after(Some(n));
        s = TableStore::new(f, LAYOUT).unwrap();
        let mut buf = vec![0u8; SLOT as usize];
        s.scan(&mut buf, valid);
        let done = op(&mut s).is_ok();
        let ops = s.flash().ops();
        let mut after = boot(s.into_flash().into_inner());
        let got = active_table(&mut after);
        assert!(
            allowed.contains(&got),
            "cut after {n} ops: active table is {:?}",
            got.as_ref().map(|t| &t[..4])
        );
        if done {
            assert!(ops <= n + 1);
            return n;
        }
    }
    unreachable!()
}

#[test]
fn empty_flash_boots_without_table() {
    let s = fresh();
    assert_eq!(s.active(), None);
    assert_eq!(s.standby(), None);
}

#[test]
fn commit_to_empty_flash_cut_everywhere() {
    let start = fresh().into_flash().into_inner();
    let t1 = table(1, 5000);
    let n = cut_everywhere(&start, &[None, Some(t1.clone())], |s| s.commit(&t1, valid));
    // 4 erases + 20 chunk writes + 1 header write: 25 cut points tested.
    assert_eq!(n, 4 + 5000_usize.div_ceil(256) + 1);
}

#[test]
fn commit_over_one_table_cut_everywhere() {
    let t1 = table(1, 3000);
    let t2 = table(2, 7001);
    let mut s = fresh();
    let i1 = s.commit(&t1, valid).unwrap();
    assert_eq!((i1.slot, i1.seq), (Slot::A, 1));
    let start = s.into_flash().into_inner();
    cut_everywhere(&start, &[Some(t1.clone()), Some(t2.clone())], |s| {
        s.commit(&t2, valid)
    });
    let mut s = boot(start);
    let i2 = s.commit(&t2, valid).unwrap();
    assert_eq!((i2.slot, i2.seq), (Slot::B, 2));
    assert_eq!(
        active_table(&mut boot(s.into_flash().into_inner())),
        Some(t2)
    );
}

#[test]
fn commit_over_two_tables_erases_only_the_older() {
    let (t1, t2, t3) = (table(1, 3000), table(2, 4000), table(3, 100));
    let mut s = fresh();
    s.commit(&t1, valid).unwrap();
    s.commit(&t2, valid).unwrap();
    assert_eq!(s.standby().map(|i| i.seq), Some(1));
    let start = s.into_flash().into_inner();
    cut_everywhere(&start, &[Some(t2.clone()), Some(t3.clone())], |s| {
        s.commit(&t3, valid)
    });
    let mut s = boot(start);
    let i3 = s.commit(&t3, valid).unwrap();
    assert_eq!((i3.slot, i3.seq), (Slot::A, 3));
    assert_eq!(s.standby().map(|i| i.seq), Some(2));
}

#[test]
fn rollback_cut_everywhere_and_commit_after_it() {
    let (t1, t2, t3) = (table(1, 3000), table(2, 4000), table(3, 999));
    let mut s = fresh();
    s.commit(&t1, valid).unwrap();
    s.commit(&t2, valid).unwrap();
    let start = s.into_flash().into_inner();
    let n = cut_everywhere(&start, &[Some(t1.clone()), Some(t2.clone())], |s| {
        s.rollback()
    });
    assert_eq!(n, 1, "a rollback is one write");
    let mut s = boot(start);
    let back = s.rollback().unwrap();
    assert_eq!((back.slot, back.seq), (Slot::A, 1));
    assert_eq!(s.standby(), None);
    // Nothing left to roll back to.
    assert_eq!(s.rollback(), Err(StoreError::NothingToRollBackTo));
    let mut rebooted = boot(s.into_flash().into_inner());
    assert_eq!(active_table(&mut rebooted), Some(t1.clone()));
    // The next commit goes to the revoked slot, above the active sequence.
    let start = rebooted.into_flash().into_inner();
    cut_everywhere(&start, &[Some(t1.clone()), Some(t3.clone())], |s| {
        s.commit(&t3, valid)
    });
    let mut s = boot(start);
    let i3 = s.commit(&t3, valid).unwrap();
    assert_eq!((i3.slot, i3.seq), (Slot::B, 2));
}

#[test]
fn invalid_tables_are_refused_before_any_write() {
    let mut s = fresh();
    let t1 = table(1, 100);
    s.commit(&t1, valid).unwrap();
    let before = s.flash().contents().to_vec();
    let mut bad = table(2, 100);
    bad[0] = b'X';
    assert_eq!(s.commit(&bad, valid), Err(StoreError::InvalidTable));
    assert_eq!(
        s.commit(&vec![0; SLOT as usize], valid),
        Err(StoreError::TooLarge)
    );
    assert_eq!(s.flash().contents(), &before[..]);
}

#[test]
fn bit_rot_in_the_newest_slot_falls_back_to_the_other() {
    let (t1, t2) = (table(1, 3000), table(2, 4000));
    let mut s = fresh();
    s.commit(&t1, valid).unwrap();
    s.commit(&t2, valid).unwrap();
    let mut flash = s.into_flash();
    // One bit in slot B's table.
    flash.contents_mut()[SLOT as usize + 64 + 1234] ^= 0x10;
    let mut s = boot(flash.into_inner());
    assert_eq!(s.active().map(|i| i.seq), Some(1));
    assert_eq!(active_table(&mut s), Some(t1));
}

#[test]
fn validation_applies_at_boot_too() {
    let mut s = fresh();
    s.commit(&table(1, 100), valid).unwrap();
    let f = s.into_flash().into_inner();
    let mut s = TableStore::new(Flash::from_contents(f), LAYOUT).unwrap();
    let mut buf = vec![0u8; SLOT as usize];
    s.scan(&mut buf, |_| false);
    assert_eq!(s.active(), None);
}

#[test]
fn layout_must_fit_the_flash() {
    let f = Flash::new_erased(vec![0; 2 * SLOT as usize]);
    let bad = Layout {
        slot_offset: [0, SLOT / 2],
        slot_bytes: SLOT,
    };
    assert!(matches!(
        TableStore::new(f, bad),
        Err(StoreError::BadLayout)
    ));
    let f = Flash::new_erased(vec![0; 2 * SLOT as usize]);
    let bad = Layout {
        slot_offset: [100, SLOT],
        slot_bytes: SLOT,
    };
    assert!(matches!(
        TableStore::new(f, bad),
        Err(StoreError::BadLayout)
    ));
}
