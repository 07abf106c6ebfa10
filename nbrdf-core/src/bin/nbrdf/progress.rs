//! The progress bars of the training commands (stderr).

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use nbrdf_core::{NbrdfError, Result};

/// An epoch bar with an ETA against `max_epochs`; `{prefix}` is empty unless set. Hidden with
/// `quiet`; indicatif's stderr target also draws nothing when stderr is not a terminal.
pub fn epoch_bar(max_epochs: usize, quiet: bool) -> Result<ProgressBar> {
    let target = if quiet {
        ProgressDrawTarget::hidden()
    } else {
        ProgressDrawTarget::stderr()
    };
    let style =
        ProgressStyle::with_template("{prefix}epoch {pos:>3}/{len} [{bar:24}] {msg}  ETA {eta}")
            .map_err(|e| NbrdfError::InvalidArgument(format!("progress bar template: {e}")))?
            .progress_chars("=> ");
    Ok(ProgressBar::with_draw_target(Some(max_epochs as u64), target).with_style(style))
}
