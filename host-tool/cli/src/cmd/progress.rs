//! The terminal side of the engine's progress events
//! (`trueaxis_engine::progress`): network training as an indicatif bar on
//! stderr, drawn only when stderr is a terminal and the command is not
//! `--json` (a pipe or a log file gets nothing of it); the stages of
//! `diagnose` and `improve` as one line each on stderr, in both modes and
//! in a pipe too (a long run's log says where it is; stdout keeps its one
//! document).

use std::io::IsTerminal;
use std::sync::Mutex;

use indicatif::{ProgressBar, ProgressStyle};
use trueaxis_engine::progress::{DiagnoseStage, Event, ImproveStage, Sink};

/// The sink for a command's progress on stderr: stage lines always, the
/// training bar when `json` is off and stderr is a terminal.
pub fn stderr(json: bool) -> Sink {
    // The bar is made at the first training event, with the total that
    // event names.
    let bar: Option<Mutex<Option<ProgressBar>>> =
        (!json && std::io::stderr().is_terminal()).then(|| Mutex::new(None));
    Sink::new(move |e| match e {
        Event::Training { .. } | Event::Finished => {
            if let Some(b) = &bar {
                draw(b, e);
            }
        }
        _ => {
            if let Some(l) = line(e) {
                eprintln!("{l}");
            }
        }
    })
}

/// The training bar's update for `e`.
fn draw(bar: &Mutex<Option<ProgressBar>>, e: &Event) {
    let Ok(mut slot) = bar.lock() else { return };
    match e {
        Event::Training {
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
                    ProgressStyle::with_template("training nn:{msg} [{bar:30}] {pos}/{len} epochs")
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
        Event::Finished => {
            if let Some(b) = slot.take() {
                b.finish_and_clear();
            }
        }
        _ => {}
    }
}

/// The stderr line of a stage event (`diagnose: ex: scoring 12
/// candidates`); `None` for the training events, which are a bar.
pub fn line(e: &Event) -> Option<String> {
    Some(match e {
        Event::Diagnose { target: t, stage } => match stage {
            DiagnoseStage::Fitting { rows, of } => {
                format!(
                    "diagnose: {t}: fitting the model to {rows} rows ({}/{})",
                    of.0, of.1
                )
            }
            DiagnoseStage::Searching { seed, effects } => format!(
                "diagnose: {t}: searching candidates (periodograms, lags) at {seed} + {effects} effect(s)"
            ),
            DiagnoseStage::Scoring { candidates } => {
                format!("diagnose: {t}: scoring {candidates} candidates")
            }
            DiagnoseStage::Added {
                step,
                add,
                held_out_rms_um,
            } => format!("diagnose: {t}: step {step}: {add} (held-out RMS {held_out_rms_um:.3} µm)"),
            DiagnoseStage::Done { of } => format!("diagnose: {t}: done ({}/{})", of.0, of.1),
        },
        Event::Improve { step, stage } => match stage {
            ImproveStage::Fitting { seed, adds, rows } => format!(
                "improve: step {step}: fitting {seed}{} to {rows} rows",
                adds.iter().map(|a| format!(" + {a}")).collect::<String>()
            ),
            ImproveStage::Diagnosing => format!("improve: step {step}: diagnosing"),
        },
        Event::Training { .. } | Event::Finished => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stage_events_read_as_the_lines_diagnose_and_improve_always_printed() {
        let d = |stage| {
            line(&Event::Diagnose {
                target: "ey",
                stage,
            })
            .unwrap()
        };
        assert_eq!(
            d(DiagnoseStage::Fitting {
                rows: 324,
                of: (2, 3)
            }),
            "diagnose: ey: fitting the model to 324 rows (2/3)"
        );
        assert_eq!(
            d(DiagnoseStage::Searching {
                seed: "cubic19".into(),
                effects: 1
            }),
            "diagnose: ey: searching candidates (periodograms, lags) at cubic19 + 1 effect(s)"
        );
        assert_eq!(
            d(DiagnoseStage::Scoring { candidates: 12 }),
            "diagnose: ey: scoring 12 candidates"
        );
        assert_eq!(
            d(DiagnoseStage::Added {
                step: 2,
                add: "drift:target=ey".into(),
                held_out_rms_um: 0.21049
            }),
            "diagnose: ey: step 2: drift:target=ey (held-out RMS 0.210 µm)"
        );
        assert_eq!(
            d(DiagnoseStage::Done { of: (2, 3) }),
            "diagnose: ey: done (2/3)"
        );
        let i = |stage| line(&Event::Improve { step: 3, stage }).unwrap();
        assert_eq!(
            i(ImproveStage::Fitting {
                seed: "cubic19".into(),
                adds: vec!["drift:target=ey".into(), "abbe:target=ex".into()],
                rows: 324
            }),
            "improve: step 3: fitting cubic19 + drift:target=ey + abbe:target=ex to 324 rows"
        );
        assert_eq!(i(ImproveStage::Diagnosing), "improve: step 3: diagnosing");
        assert_eq!(line(&Event::Finished), None);
    }
}
