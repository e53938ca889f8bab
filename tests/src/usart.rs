//! USART1 through the PAC as the link's byte stream in QEMU (where
//! `qemu-system-arm -serial tcp:…` connects it to a TCP socket the host
//! tool talks to).
//!
//! Receive is interrupt driven into a ring buffer. The handler must read DR
//! itself: QEMU's USART interrupt line is level triggered and stays high
//! while RXNE is set, so a handler that only woke the task would re-enter
//! forever and starve it. QEMU's model holds one received byte at a time
//! and back-pressures the socket until the guest reads it, so when the ring
//! is full the handler masks the interrupt (leaving the byte in DR) and the
//! reader unmasks it once it has made room — no byte is ever dropped.
//! Transmission completes immediately in QEMU (TXE is always set), so
//! writes are a polled loop.

use core::cell::RefCell;
use core::future::poll_fn;
use core::task::Poll;

use cortex_m::peripheral::NVIC;
use critical_section::Mutex;
use embassy_sync::waitqueue::AtomicWaker;
use heapless::Deque;
use stm32_metapac::{interrupt, Interrupt, USART1};

/// Received bytes not yet read by the task (a link frame is at most a few
/// hundred bytes; a full ring only slows the sender down).
const RX_BYTES: usize = 512;

static RX: Mutex<RefCell<Deque<u8, RX_BYTES>>> = Mutex::new(RefCell::new(Deque::new()));
static RX_WAKER: AtomicWaker = AtomicWaker::new();

/// USART1, enabled for receive (interrupt driven) and transmit (polled).
#[derive(Debug)]
pub struct Usart1 {
    _private: (),
}

impl Usart1 {
    /// Enables USART1 (QEMU ignores the baud rate; 115 200 Bd at 84 MHz
    /// APB2 is set for form's sake) and its RXNE interrupt.
    pub fn new() -> Self {
        USART1
            .brr()
            .write_value(stm32_metapac::usart::regs::Brr(84_000_000 / 115_200));
        USART1.cr1().write(|w| {
            w.set_ue(true);
            w.set_te(true);
            w.set_re(true);
            w.set_rxneie(true);
        });
        unmask();
        Self { _private: () }
    }

    /// Waits for at least one received byte and returns up to `buf.len()`.
    pub async fn read(&mut self, buf: &mut [u8]) -> usize {
        poll_fn(|cx| {
            RX_WAKER.register(cx.waker());
            let n = critical_section::with(|cs| {
                let mut rx = RX.borrow_ref_mut(cs);
                let mut n = 0;
                while n < buf.len() {
                    match rx.pop_front() {
                        Some(b) => {
                            buf[n] = b;
                            n += 1;
                        }
                        None => break,
                    }
                }
                n
            });
            // There is room now: let the handler take the byte it may have
            // left in DR when the ring was full.
            unmask();
            if n > 0 {
                Poll::Ready(n)
            } else {
                Poll::Pending
            }
        })
        .await
    }

    /// Sends `bytes` (blocking; instantaneous in QEMU).
    pub fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            while !USART1.sr().read().txe() {}
            USART1.dr().write(|w| w.set_dr(u16::from(b)));
        }
    }
}

impl Default for Usart1 {
    fn default() -> Self {
        Self::new()
    }
}

fn unmask() {
    // The only unsafe step: unmasking cannot break a critical section here
    // (the handler takes its own), it only lets the handler run.
    #[allow(unsafe_code)]
    unsafe {
        NVIC::unmask(Interrupt::USART1)
    };
}

#[interrupt]
fn USART1() {
    critical_section::with(|cs| {
        let mut rx = RX.borrow_ref_mut(cs);
        while USART1.sr().read().rxne() {
            if rx.is_full() {
                NVIC::mask(Interrupt::USART1);
                break;
            }
            // Reading DR clears RXNE and lowers the interrupt line.
            let _ = rx.push_back(USART1.dr().read().dr() as u8);
        }
    });
    RX_WAKER.wake();
}
