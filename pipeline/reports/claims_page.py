"""``CLAIMS.md`` and ``CLAIMS.html``: the evaluated claims register, rendered."""

from __future__ import annotations

from pathlib import Path

from pipeline.claims.evaluate import ClaimsOutcome
from pipeline.claims.record import KIND_INTROS, KIND_NAMES, STATUSES, kind_counts
from pipeline.claims.seed_note import differences, fmt
from pipeline.paths import display_path
from pipeline.reports.templating import render


def render_claims(outcome: ClaimsOutcome, out_dir: Path) -> Path:
    """Render the register beside its ``claims.json``; returns the Markdown page."""
    ctx = {"results": outcome.results, "claims_file": display_path(outcome.claims_file.source),
           "note_rows": outcome.note_rows,
           "note_regimes": outcome.note_regimes, "range_marks": outcome.range_marks,
           "note_differences": differences(outcome.note_rows),
           "fmt": fmt, "code_version": outcome.source_version,
           "counts": {s: outcome.count(s) for s in STATUSES}, "kind_names": KIND_NAMES,
           "kind_intro": KIND_INTROS,
           # The same summary as the CLI's and the index's, every status of each kind.
           "kind_counts": kind_counts({"claims": [{"kind": r.claim.kind, "status": r.status}
                                                  for r in outcome.results]})}
    md = render("claims.md.j2", Path(out_dir) / "CLAIMS.md", **ctx)
    render("claims.html.j2", Path(out_dir) / "CLAIMS.html", **ctx)
    return md
