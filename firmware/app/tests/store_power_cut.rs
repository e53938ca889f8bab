//! The A/B store against a flash that loses power, as the STM32F405 has
//! it: the slots where memory.x puts them (TABLE_A / TABLE_B, sectors 10
//! and 11 of the 1 MiB flash), 128 KiB sectors erased in one step, 32-bit
//! word programming, and model-core's own parse + load as the validator
//! (the one the board uses). For each scenario the power is cut at every
//! operation — a write torn at every one of its words (a word partially
//! programmed, seeded), an erase torn as seeded mixes of old and erased
//! bits and as an ordered prefix — then the board "reboots" on what is
//! left: a valid table, the old or the new one, must be active, and the
//! interrupted operation must succeed when repeated. Also the same cuts
//! through the link server's Commit and Rollback (an answered commit must
//! survive), the revoked-slot case, bit rot, and the sector map itself.

use std::cell::RefCell;

use trueaxis_app::engine::Engine;
use trueaxis_app::memflash::{Cut, MemFlash};
use trueaxis_app::model::{load_into, ModelBuf};
use trueaxis_app::server::{Server, ServerConfig};
use trueaxis_app::sim::{sample_table, sim_engine_config};
use trueaxis_app::store::{Layout, StoreError, TableStore};
use trueaxis_protocol::slot::{BODY_AT, REVOKE_AT, REVOKE_BYTES};
use trueaxis_protocol::{table_id, Request, Response, Slot, SlotInfo, MAX_CHUNK_BYTES};

/// The F405's flash: 4-byte program, 128 KiB erase (sectors 5–11; the
/// smaller sectors 0–4 hold code, never a slot — see
/// `memory_x_slots_are_whole_f405_sectors`).
type Flash = MemFlash<Vec<u8>, 4, { 128 * 1024 }>;

const FLASH_BASE: u32 = 0x0800_0000;
const FLASH_BYTES: usize = 1024 * 1024;
/// The F405's sector sizes, KiB, from 0x0800_0000 (RM0090 table 5).
const F405_SECTORS_KIB: [u32; 12] = [16, 16, 16, 16, 64, 128, 128, 128, 128, 128, 128, 128];

/// ORIGIN and LENGTH of `region` in the repository's memory.x.
fn memory_x(region: &str) -> (u32, u32) {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../memory.x"))
        .expect("memory.x");
    let line = text
        .lines()
        .map(str::trim)
        .find(|l| l.starts_with(region) && l.contains("ORIGIN"))
        .unwrap_or_else(|| panic!("no {region} in memory.x"));
    let field = |name: &str| {
        let v = line.split(name).nth(1).unwrap();
        let tok: String = v
            .trim_start_matches([' ', '='])
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric())
            .collect();
        match tok.strip_suffix('K') {
            Some(k) => k.parse::<u32>().unwrap() * 1024,
            None => u32::from_str_radix(tok.trim_start_matches("0x"), 16).unwrap(),
        }
    };
    (field("ORIGIN"), field("LENGTH"))
}

fn layout() -> Layout {
    let (a, len) = memory_x("TABLE_A");
    let (b, _) = memory_x("TABLE_B");
    Layout {
        slot_offset: [a - FLASH_BASE, b - FLASH_BASE],
        slot_bytes: len,
    }
}

/// The board's validator: model-core's parse + load.
fn valid(b: &[u8]) -> bool {
    thread_local!(static BUF: RefCell<Box<ModelBuf>> = RefCell::new(Box::default()));
    BUF.with(|m| load_into(b, &mut m.borrow_mut()).is_ok())
}

fn table(v: u32) -> Vec<u8> {
    let t = sample_table(v);
    assert!(valid(&t));
    t
}

fn boot(contents: Vec<u8>) -> TableStore<Flash> {
    let mut s = TableStore::new(Flash::from_contents(contents), layout()).unwrap();
    let mut buf = vec![0u8; 64 * 1024];
    s.scan(&mut buf, valid);
    s
}

fn active_table(s: &mut TableStore<Flash>) -> Option<Vec<u8>> {
    let info = s.active()?;
    let mut buf = vec![0u8; 64 * 1024];
    Some(s.read_table(info, &mut buf).unwrap().to_vec())
}

fn fresh() -> TableStore<Flash> {
    boot(Flash::new_erased(vec![0; FLASH_BYTES]).into_inner())
}

/// Every way the power is cut during operation `op`: a write torn at each
/// of its words (two seeds each; words past its end: done whole), an erase
/// as three seeded mixes and the ordered prefix.
fn cuts(op: usize) -> impl Iterator<Item = Cut> {
    let words = (0..=64usize).flat_map(move |word| {
        [11u64, 12].map(|seed| Cut {
            op,
            word,
            seed: seed + word as u64 * 100,
            ordered_erase: false,
        })
    });
    let erases = [1u64, 2, 3, 4].map(|seed| Cut {
        op,
        word: 0,
        seed,
        ordered_erase: seed == 4,
    });
    words.chain(erases)
}

/// Runs `op` on a store booted from `start` with the power cut at every
/// operation and word ([`cuts`]); after each, reboots and checks that the
/// active table is one of `allowed` and that `op` then succeeds on the
/// rebooted store. Returns the number of operations of the uncut run.
fn cut_everywhere(
    start: &[u8],
    allowed: &[Option<Vec<u8>>],
    mut op: impl FnMut(&mut TableStore<Flash>) -> Result<SlotInfo, StoreError>,
) -> usize {
    let mut s = boot(start.to_vec());
    op(&mut s).expect("the uncut operation succeeds");
    let n_ops = s.flash().ops();
    let mut tried = 0;
    for n in 0..n_ops {
        for cut in cuts(n) {
            let mut s = boot(start.to_vec());
            let mut f = s.into_flash();
            f.cut_power(Some(cut));
            s = TableStore::new(f, layout()).unwrap();
            let mut buf = vec![0u8; 64 * 1024];
            s.scan(&mut buf, valid);
            assert!(op(&mut s).is_err(), "{cut:?}: the cut op must fail");
            let mut after = boot(s.into_flash().into_inner());
            let got = active_table(&mut after);
            assert!(
                allowed.contains(&got),
                "{cut:?}: active table is {:?}",
                got.map(|t| table_id(&t))
            );
            // Never bricked: the same operation goes through now (a
            // rollback may have taken effect before the cut: then there is
            // nothing left to roll back to).
            match op(&mut after) {
                Ok(_) | Err(StoreError::NothingToRollBackTo) => {}
                Err(e) => panic!("{cut:?}: repeated operation failed: {e:?}"),
            }
            tried += 1;
        }
    }
    assert!(tried > 0);
    n_ops
}

#[test]
fn memory_x_slots_are_whole_f405_sectors() {
    let mut starts = Vec::new();
    let mut at = FLASH_BASE;
    for kib in F405_SECTORS_KIB {
        starts.push((at, kib * 1024));
        at += kib * 1024;
    }
    assert_eq!(at - FLASH_BASE, FLASH_BYTES as u32);
    let (code, code_len) = memory_x("FLASH");
    for region in ["TABLE_A", "TABLE_B"] {
        let (o, len) = memory_x(region);
        assert!(
            starts.contains(&(o, len)),
            "{region} ({o:#x}, {len:#x}) is not one F405 sector"
        );
        assert!(o >= code + code_len, "{region} overlaps the code");
    }
    let l = layout();
    assert_eq!(l.slot_offset, [0xC_0000, 0xE_0000]);
    assert!(TableStore::new(Flash::new_erased(vec![0; FLASH_BYTES]), l).is_ok());
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
    let t1 = table(0);
    let n = cut_everywhere(&start, &[None, Some(t1.clone())], |s| s.commit(&t1, valid));
    // One sector erase, the table in 256-byte writes, the header.
    assert_eq!(n, 1 + t1.len().div_ceil(256) + 1);
}

#[test]
fn commit_over_one_table_cut_everywhere() {
    let (t1, t2) = (table(0), table(1));
    let mut s = fresh();
    let i1 = s.commit(&t1, valid).unwrap();
    assert_eq!((i1.slot, i1.seq), (Slot::A, 1));
    let start = s.into_flash().into_inner();
    cut_everywhere(&start, &[Some(t1.clone()), Some(t2.clone())], |s| {
        s.commit(&t2, valid)
    });
}

#[test]
fn commit_over_two_tables_erases_only_the_older() {
    let (t1, t2, t3) = (table(0), table(1), table(2));
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
    let (t1, t2, t3) = (table(0), table(1), table(2));
    let mut s = fresh();
    s.commit(&t1, valid).unwrap();
    s.commit(&t2, valid).unwrap();
    let start = s.into_flash().into_inner();
    let n = cut_everywhere(&start, &[Some(t1.clone()), Some(t2.clone())], |s| {
        s.rollback()
    });
    assert_eq!(n, 2, "a rollback is two writes: the marker, the magic");
    let mut s = boot(start);
    let back = s.rollback().unwrap();
    assert_eq!((back.slot, back.seq), (Slot::A, 1));
    assert_eq!(s.standby(), None);
    assert_eq!(s.rollback(), Err(StoreError::NothingToRollBackTo));
    let mut rebooted = boot(s.into_flash().into_inner());
    assert_eq!(active_table(&mut rebooted), Some(t1.clone()));
    // The next commit goes to the revoked slot, above the active sequence;
    // no cut in it brings the revoked t2 back.
    let start = rebooted.into_flash().into_inner();
    cut_everywhere(&start, &[Some(t1.clone()), Some(t3.clone())], |s| {
        s.commit(&t3, valid)
    });
    let mut s = boot(start);
    let i3 = s.commit(&t3, valid).unwrap();
    assert_eq!((i3.slot, i3.seq), (Slot::B, 2));
}

/// The case store.rs documents: after a rollback the revoked slot has the
/// higher sequence number; an erase of it torn so that its revoke marker
/// came back erased while everything else survived must not resurrect the
/// rolled-back table (it did when a rollback only revoked).
#[test]
fn a_torn_erase_of_the_revoked_slot_never_brings_it_back() {
    let (t1, t2) = (table(0), table(1));
    let mut s = fresh();
    s.commit(&t1, valid).unwrap();
    s.commit(&t2, valid).unwrap();
    s.rollback().unwrap();
    let mut contents = s.into_flash().into_inner();
    let b = layout().slot_offset[1] as usize;
    // The worst order: the marker erased, nothing else.
    contents[b + REVOKE_AT as usize..][..REVOKE_BYTES].fill(0xFF);
    let mut s = boot(contents.clone());
    assert_eq!(active_table(&mut s), Some(t1.clone()));
    assert_eq!(s.standby(), None);
    // And seeded mixes over the whole header and marker.
    for seed in 1..200u64 {
        let mut c = contents.clone();
        let mut x = seed;
        for byte in &mut c[b..b + BODY_AT as usize] {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            *byte |= x as u8;
        }
        let mut s = boot(c);
        assert_eq!(active_table(&mut s), Some(t1.clone()), "seed {seed}");
    }
}

#[test]
fn invalid_tables_are_refused_before_any_write() {
    let mut s = fresh();
    s.commit(&table(0), valid).unwrap();
    let before = s.flash().contents().to_vec();
    // Sealed (right CRC) but not a table model-core accepts.
    let mut bad = table(1);
    bad[8] ^= 0xFF;
    let body = bad.len() - 4;
    let crc = trueaxis_protocol::FRAME_CRC.checksum(&bad[..body]);
    bad[body..].copy_from_slice(&crc.to_le_bytes());
    assert_eq!(s.commit(&bad, valid), Err(StoreError::InvalidTable));
    assert_eq!(
        s.commit(&vec![0; 128 * 1024], valid),
        Err(StoreError::TooLarge)
    );
    assert_eq!(s.flash().contents(), &before[..]);
}

#[test]
fn bit_rot_in_the_newest_slot_falls_back_to_the_other() {
    let (t1, t2) = (table(0), table(1));
    let mut s = fresh();
    s.commit(&t1, valid).unwrap();
    s.commit(&t2, valid).unwrap();
    let mut flash = s.into_flash();
    let b = layout().slot_offset[1] as usize;
    flash.contents_mut()[b + BODY_AT as usize + 123] ^= 0x10;
    let mut s = boot(flash.into_inner());
    assert_eq!(s.active().map(|i| i.seq), Some(1));
    assert_eq!(active_table(&mut s), Some(t1));
}

#[test]
fn validation_applies_at_boot_too() {
    let mut s = fresh();
    s.commit(&table(0), valid).unwrap();
    let f = s.into_flash().into_inner();
    let mut s = TableStore::new(Flash::from_contents(f), layout()).unwrap();
    let mut buf = vec![0u8; 64 * 1024];
    s.scan(&mut buf, |_| false);
    assert_eq!(s.active(), None);
}

#[test]
fn layout_must_fit_the_flash() {
    let f = Flash::new_erased(vec![0; FLASH_BYTES]);
    let mut bad = layout();
    bad.slot_offset[1] = bad.slot_offset[0] + 64 * 1024;
    assert!(matches!(
        TableStore::new(f, bad),
        Err(StoreError::BadLayout)
    ));
    let f = Flash::new_erased(vec![0; FLASH_BYTES]);
    let mut bad = layout();
    bad.slot_offset[1] = FLASH_BYTES as u32;
    assert!(matches!(
        TableStore::new(f, bad),
        Err(StoreError::BadLayout)
    ));
}

/// A link server over the F405 flash, booted on `contents`.
struct Board {
    engine: RefCell<Engine<'static>>,
    server: Server<'static, 'static, Flash>,
}

impl Board {
    fn boot(contents: Vec<u8>, cut: Option<Cut>) -> Self {
        let engine = RefCell::new(Engine::new(sim_engine_config()).unwrap());
        let stage: &'static mut [u8] = Box::leak(vec![0u8; 24 * 1024].into_boxed_slice());
        let m1: &'static mut ModelBuf = Box::leak(Box::default());
        let m2: &'static mut ModelBuf = Box::leak(Box::default());
        let mut flash = Flash::from_contents(contents);
        flash.cut_power(cut);
        // Booting only reads: the cut counts from the request's first
        // erase or write.
        let server = Server::new(
            TableStore::new(flash, layout()).unwrap(),
            stage,
            [m1, m2],
            ServerConfig {
                firmware: [0, 0, 0],
                quiet_ms: 0,
                model_budget_instr: model_core::board::MODEL_BUDGET_INSTR,
            },
        );
        let mut b = Self { engine, server };
        b.server.boot(&b.engine);
        b
    }

    fn active_crc(&self) -> Option<u32> {
        self.engine.borrow().active().map(|a| a.crc32)
    }

    fn request(&mut self, r: Request<'_>) -> Response {
        self.server.handle(r, 1_000_000, &self.engine)
    }

    fn upload_and_commit(&mut self, t: &[u8]) -> Response {
        let r = self.request(Request::UploadBegin {
            size: t.len() as u32,
            crc32: table_id(t),
        });
        assert!(matches!(r, Response::UploadAck { .. }), "{r:?}");
        for (i, data) in t.chunks(MAX_CHUNK_BYTES).enumerate() {
            let offset = (i * MAX_CHUNK_BYTES) as u32;
            let r = self.request(Request::UploadChunk { offset, data });
            assert!(matches!(r, Response::UploadAck { .. }), "{r:?}");
        }
        self.request(Request::Commit)
    }

    fn contents(self) -> Vec<u8> {
        self.server.into_store().into_flash().into_inner()
    }
}

/// The server's Commit and Rollback with the power cut at every operation
/// and word: after the reboot the old or the new table runs, and a
/// `Committed` / `RolledBack` answer (the host prints success) always
/// means the new state survived.
#[test]
fn the_servers_commit_and_rollback_cut_everywhere() {
    let (t1, t2) = (table(0), table(1));
    let mut b = Board::boot(Flash::new_erased(vec![0; FLASH_BYTES]).into_inner(), None);
    assert!(matches!(b.upload_and_commit(&t1), Response::Committed(_)));
    let start = b.contents();
    let (c1, c2) = (Some(table_id(&t1)), Some(table_id(&t2)));
    let mut answered = 0;
    for n in 0..(1 + t2.len().div_ceil(256) + 1) {
        for cut in cuts(n) {
            let mut b = Board::boot(start.clone(), Some(cut));
            let r = b.upload_and_commit(&t2);
            let ok = matches!(r, Response::Committed(_));
            answered += usize::from(ok);
            let after = Board::boot(b.contents(), None);
            let got = after.active_crc();
            assert!(got == c1 || got == c2, "{cut:?}: {got:?}");
            if ok {
                assert_eq!(got, c2, "{cut:?}: answered Committed, lost");
            }
        }
    }
    assert_eq!(answered, 0, "a cut commit never answers Committed");

    // Rollback from t2 to t1, cut at both writes.
    let mut b = Board::boot(start, None);
    assert!(matches!(b.upload_and_commit(&t2), Response::Committed(_)));
    let start = b.contents();
    for n in 0..2 {
        for cut in cuts(n) {
            let mut b = Board::boot(start.clone(), Some(cut));
            let ok = matches!(b.request(Request::Rollback), Response::RolledBack(_));
            let after = Board::boot(b.contents(), None);
            let got = after.active_crc();
            assert!(got == c1 || got == c2, "{cut:?}: {got:?}");
            if ok {
                assert_eq!(got, c1, "{cut:?}: answered RolledBack, undone");
            }
        }
    }
}
