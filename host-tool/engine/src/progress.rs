//! Progress as typed events. The engine never draws or prints: a long
//! computation — a network's training in `fit`, each target's stages in
//! `diagnose`, each step of `improve` — sends [`Event`]s to the [`Sink`]
//! its caller gave, and the caller renders them (the CLI's
//! `cmd/progress.rs`: a bar on a terminal, lines on stderr; a test collects
//! them; a GUI could draw its own). One type for every module, so a front
//! end handles all of them in one place.

use std::sync::Arc;

/// What a long computation is doing.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// Training `nn:<hidden>`: `done` of `total` epochs over all restarts.
    Training {
        /// Hidden neurons of the network.
        hidden: usize,
        /// The restart running (1-based).
        restart: usize,
        /// Restarts in all.
        restarts: usize,
        /// Epochs done over all restarts.
        done: u64,
        /// Epochs at most over all restarts.
        total: u64,
        /// Mean squared training error of the last epoch (scaled units).
        train_mse: f64,
    },
    /// The training is over.
    Finished,
    /// `diagnose` reached a stage of one target (the targets run in
    /// parallel: events of different targets interleave).
    Diagnose {
        /// The target (`ex`, `ey`, `ez`).
        target: &'static str,
        /// What it is doing.
        stage: DiagnoseStage,
    },
    /// `improve` reached a stage of one step.
    Improve {
        /// The step (1-based).
        step: usize,
        /// What it is doing.
        stage: ImproveStage,
    },
}

/// A stage of one target's diagnosis.
#[derive(Clone, Debug, PartialEq)]
pub enum DiagnoseStage {
    /// Fitting the model to the target's rows; the target is the
    /// `of.0`-th of `of.1`.
    Fitting {
        /// Rows where the target is measured.
        rows: usize,
        /// (this target's place, targets in all), 1-based.
        of: (usize, usize),
    },
    /// Searching the candidate library at the model `seed` + `effects`.
    Searching {
        /// The seed (`cubic19`, `kinematic`).
        seed: String,
        /// Effects in the model beside the seed.
        effects: usize,
    },
    /// Scoring the candidates the search proposed.
    Scoring {
        /// Candidates proposed.
        candidates: usize,
    },
    /// A step of the BIC-ordered path added an effect.
    Added {
        /// The path's step (1-based).
        step: usize,
        /// The effect added, as `fit --add` takes it.
        add: String,
        /// The block-held-out RMS after the step, µm.
        held_out_rms_um: f64,
    },
    /// The target is diagnosed.
    Done {
        /// (this target's place, targets in all), 1-based.
        of: (usize, usize),
    },
}

/// A stage of one improve step.
#[derive(Clone, Debug, PartialEq)]
pub enum ImproveStage {
    /// Fitting the model `seed` + `adds` to the data.
    Fitting {
        /// The seed.
        seed: String,
        /// The effects added so far, as `fit --add` takes them.
        adds: Vec<String>,
        /// Rows of the data set.
        rows: usize,
    },
    /// Diagnosing the fitted model.
    Diagnosing,
}

/// A receiver of [`Event`]s.
pub type Receiver = dyn Fn(&Event) + Send + Sync;

/// Where [`Event`]s go: a front end's callback, or nowhere. Cheap to clone
/// and shareable between threads (diagnose's targets run in parallel).
#[derive(Clone, Default)]
pub struct Sink(Option<Arc<Receiver>>);

impl Sink {
    /// Events go to `f`.
    pub fn new(f: impl Fn(&Event) + Send + Sync + 'static) -> Self {
        Sink(Some(Arc::new(f)))
    }

    /// Events go nowhere.
    pub fn none() -> Self {
        Sink(None)
    }

    /// Sends `e` to the receiver, if there is one.
    pub fn emit(&self, e: &Event) {
        if let Some(f) = &self.0 {
            f(e);
        }
    }
}

impl std::fmt::Debug for Sink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(if self.0.is_some() {
            "Sink(callback)"
        } else {
            "Sink(none)"
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    #[test]
    fn a_sink_hands_each_event_to_its_receiver_and_none_drops_them() {
        let got = Arc::new(Mutex::new(Vec::new()));
        let g = Arc::clone(&got);
        let sink = Sink::new(move |e| g.lock().unwrap().push(e.clone()));
        let e = Event::Improve {
            step: 2,
            stage: ImproveStage::Diagnosing,
        };
        sink.clone().emit(&e);
        Sink::none().emit(&Event::Finished);
        assert_eq!(*got.lock().unwrap(), [e]);
    }
}
