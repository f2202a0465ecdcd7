//! Progress on stderr, fed by the library's callback ([`mps_runner::run::Progress`]): on a
//! terminal an `indicatif` bar per running run (simulated time, steps/s, particles, time
//! left) and, for a sweep, one bar of points done / running / left; elsewhere (CI logs,
//! files) one plain line per tenth of the simulated time. `--quiet` makes none.
use std::collections::HashMap;
use std::io::IsTerminal;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use mps_runner::run::{Progress, ProgressFn};

/// Bar positions are simulated time in microseconds.
const TICKS_PER_S: f64 = 1e6;

/// One run's display state.
struct Shown {
    bar: Option<ProgressBar>,
    started: Instant,
    first_step: u64,
    /// The next tenth of the end time at which a plain line is due.
    next_line: u32,
    /// Last message update (the message is rebuilt at most 10 times a second).
    last_message: Option<Instant>,
}

/// Where progress goes: bars on a terminal, plain lines otherwise.
pub struct Display {
    terminal: bool,
    multi: MultiProgress,
    runs: Mutex<HashMap<String, Shown>>,
    points: Option<ProgressBar>,
}

impl Display {
    /// `None` when quiet. Bars only when stderr is a terminal.
    pub fn new(quiet: bool) -> Option<Arc<Self>> {
        if quiet {
            return None;
        }
        let terminal = std::io::stderr().is_terminal();
        let multi = MultiProgress::with_draw_target(if terminal {
            ProgressDrawTarget::stderr_with_hz(10)
        } else {
            ProgressDrawTarget::hidden()
        });
        Some(Arc::new(Self {
            terminal,
            multi,
            runs: Mutex::new(HashMap::new()),
            points: None,
        }))
    }

    /// For a sweep of `total` points: a bar of points done / running / left on top.
    pub fn for_sweep(quiet: bool, total: usize) -> Option<Arc<Self>> {
        let mut display = Arc::into_inner(Self::new(quiet)?).expect("just made");
        if display.terminal {
            let bar = display.multi.add(ProgressBar::new(total as u64));
            bar.set_style(
                ProgressStyle::with_template(
                    "points [{bar:30.green/white}] {pos}/{len} done, {msg} [{elapsed_precise}]",
                )
                .expect("a valid template")
                .progress_chars("=> "),
            );
            bar.set_message(format!("0 running, {total} left"));
            display.points = Some(bar);
        }
        Some(Arc::new(display))
    }

    /// The callback to hand to the library.
    pub fn callback(self: &Arc<Self>) -> ProgressFn {
        let me = Arc::clone(self);
        Arc::new(move |p: &Progress| me.update(p))
    }

    fn update(&self, p: &Progress) {
        let mut runs = self.runs.lock().unwrap_or_else(|e| e.into_inner());
        let now = Instant::now();
        let shown = runs.entry(p.run.to_string()).or_insert_with(|| Shown {
            bar: self.terminal.then(|| self.new_bar(p)),
            started: now,
            first_step: p.step,
            next_line: (10.0 * p.time_s / p.end_s).floor() as u32 + 1,
            last_message: None,
        });
        let wall_s = now.duration_since(shown.started).as_secs_f64();
        let steps_per_s = if wall_s > 0.0 {
            (p.step - shown.first_step) as f64 / wall_s
        } else {
            0.0
        };
        let end = if p.stops_early {
            format!("{} s cap", p.end_s)
        } else {
            format!("{} s", p.end_s)
        };
        match &shown.bar {
            Some(bar) => {
                bar.set_position((p.time_s * TICKS_PER_S) as u64);
                if shown
                    .last_message
                    .is_none_or(|t| now.duration_since(t) >= Duration::from_millis(100))
                {
                    shown.last_message = Some(now);
                    bar.set_message(format!(
                        "t = {:.3} / {end}, step {}, {:.0} steps/s, {} particles",
                        p.time_s, p.step, steps_per_s, p.particles
                    ));
                }
            }
            None => {
                // One line per tenth of the end time, with the rate and the time left at it.
                let tenth = (10.0 * p.time_s / p.end_s + 1e-9).floor() as u32;
                if tenth >= shown.next_line {
                    shown.next_line = tenth + 1;
                    let done = p.time_s / p.end_s;
                    let left_s = if done > 0.0 {
                        wall_s * (1.0 - done) / done
                    } else {
                        f64::NAN
                    };
                    eprintln!(
                        "{}: t = {:.4} / {end}, step {}, {:.0} steps/s, {} particles, {:.1} s wall, about {:.1} s left{}",
                        p.run,
                        p.time_s,
                        p.step,
                        steps_per_s,
                        p.particles,
                        wall_s,
                        left_s,
                        if p.stops_early {
                            " at most (a stop rule may end it sooner)"
                        } else {
                            ""
                        }
                    );
                }
            }
        }
    }

    fn new_bar(&self, p: &Progress) -> ProgressBar {
        let bar = self
            .multi
            .add(ProgressBar::new((p.end_s * TICKS_PER_S) as u64));
        bar.set_style(
            ProgressStyle::with_template(
                "{prefix} [{bar:30.cyan/blue}] {percent:>3}% {msg} [{elapsed_precise}, {eta} left]",
            )
            .expect("a valid template")
            .progress_chars("=> "),
        );
        bar.set_prefix(p.run.to_string());
        bar
    }

    /// A run ended: its bar is removed (the caller prints its outcome line).
    pub fn finished(&self, run: &str) {
        let mut runs = self.runs.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(Shown { bar: Some(bar), .. }) = runs.remove(run) {
            bar.finish_and_clear();
            self.multi.remove(&bar);
        }
    }

    /// Every run ended (one run, a replay): clears the bars.
    pub fn finish_all(&self) {
        let mut runs = self.runs.lock().unwrap_or_else(|e| e.into_inner());
        for (_, shown) in runs.drain() {
            if let Some(bar) = shown.bar {
                bar.finish_and_clear();
            }
        }
    }

    /// A sweep point ended: `done` of `total`, `workers` running at most.
    pub fn point_done(&self, done: usize, total: usize, workers: usize) {
        if let Some(bar) = &self.points {
            let left = total - done;
            bar.set_position(done as u64);
            bar.set_message(format!("{} running, {left} left", workers.min(left)));
            if done == total {
                bar.finish_and_clear();
            }
        }
    }

    /// Runs `f` (which prints) with the bars hidden, so they do not tear.
    pub fn suspend<R>(&self, f: impl FnOnce() -> R) -> R {
        self.multi.suspend(f)
    }
}
