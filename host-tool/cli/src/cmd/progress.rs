//! The terminal side of the engine's progress events: an indicatif bar on
//! stderr for [`Progress`] events (network training), drawn only when
//! stderr is a terminal — a pipe, a log file or `--json` gets nothing.

use std::io::IsTerminal;
use std::sync::Mutex;

use indicatif::{ProgressBar, ProgressStyle};
use trueaxis_engine::fit::{Progress, ProgressSink};

/// A sink that draws a bar on stderr when `show` is set and stderr is a
/// terminal; otherwise one that drops every event.
pub fn bar(show: bool) -> ProgressSink {
    if !show || !std::io::stderr().is_terminal() {
        return ProgressSink::none();
    }
    // The bar is made at the first event, with the total that event names.
    let bar: Mutex<Option<ProgressBar>> = Mutex::new(None);
    ProgressSink::new(move |p| {
        let Ok(mut slot) = bar.lock() else { return };
        match p {
            Progress::Training {
                hidden,
                restart,
                restarts,
                done,
                total,
                train_mse,
            } => {
                let b = slot.get_or_insert_with(|| {
                    let b = ProgressBar::new(*total);
                    b.set_style(
                        ProgressStyle::with_template(
                            "training nn:{msg} [{bar:30}] {pos}/{len} epochs",
                        )
                        .unwrap_or_else(|_| ProgressStyle::default_bar()),
                    );
                    b
                });
                b.set_length(*total);
                b.set_position(*done);
                b.set_message(format!(
                    "{hidden} restart {restart}/{restarts} mse {train_mse:.3e}"
                ));
            }
            Progress::Finished => {
                if let Some(b) = slot.take() {
                    b.finish_and_clear();
                }
            }
        }
    })
}
