"""How much of a planned recording is there: samples planned and kept, samples lost on the
link, a killed writer (salvaged file) or an aborted run, stated in one sentence for
``inspect``, ``record``'s summary and the fit report."""

from __future__ import annotations

import re
from dataclasses import dataclass

from hframe_id.recordings.recording import Recording

_PLANNED = re.compile(r"(\d+) samples planned")


@dataclass(frozen=True)
class Completeness:
    """Samples kept against samples planned.

    Attributes
    ----------
    samples : samples in the recording.
    planned : samples the protocol planned (None when the recording does not say, e.g. an
        imported log).
    lost_in_gaps : samples missing from the sequence numbers (lost on the link).
    truncated : the file was unfinished (writer killed) and salvaged.
    aborted : the run was aborted (limit switch, link fault, user).
    """

    samples: int
    planned: int | None
    lost_in_gaps: int
    truncated: bool
    aborted: bool

    @property
    def missing(self) -> int:
        """Planned samples not in the recording (gaps included); 0 if nothing was planned."""
        if self.planned is None:
            return self.lost_in_gaps
        return max(self.planned - self.samples, self.lost_in_gaps)

    @property
    def lost_share(self) -> float:
        """``missing`` as a share of the planned samples (of the samples present plus those
        lost in gaps when nothing was planned)."""
        total = self.planned or self.samples + self.lost_in_gaps
        return self.missing / total if total else 0.0

    def statement(self) -> str | None:
        """One sentence when the recording is not the complete run, else None."""
        if not (self.truncated or self.aborted or self.missing):
            return None
        causes = []
        if self.truncated:
            causes.append("the file was unfinished (writer killed) and salvaged")
        if self.aborted:
            causes.append("the run was aborted")
        if self.lost_in_gaps:
            causes.append(f"{self.lost_in_gaps} sample(s) were lost on the link")
        of = f" of {self.planned} planned" if self.planned is not None else ""
        share = f" ({100 * self.lost_share:.1f} % lost)" if self.missing else ""
        return f"{self.samples}{of} samples{share}: {'; '.join(causes)}"


def planned_samples(recording: Recording) -> int | None:
    """Samples the recording's protocol planned: from its start event (the logger's), else
    from ``protocol.duration_s`` in the experiment metadata; None if neither says."""
    for event in recording.events:
        if event.get("kind") == "start" and (match := _PLANNED.search(str(event["reason"]))):
            return int(match.group(1))
    duration = recording.experiment.get("protocol.duration_s")
    if isinstance(duration, int | float) and recording.sample_period_s > 0:
        return round(duration / recording.sample_period_s)
    return None


def completeness(recording: Recording) -> Completeness:
    """How complete ``recording`` is (see ``Completeness``)."""
    return Completeness(
        samples=recording.n_samples,
        planned=planned_samples(recording),
        lost_in_gaps=sum(missing for _, missing in recording.sequence_gaps),
        truncated=recording.truncated,
        aborted=recording.aborted,
    )
