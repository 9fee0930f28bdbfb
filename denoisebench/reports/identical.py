"""Denoisers that gave the same numbers: said once, with the reason where it is known.

Two labels are **identical** in a run when they scored the same frames and every stored score of
every frame agrees in every digit (frame metrics and temporal metrics, at every spp and scene),
and the frames the store kept of both are the same pixels. The report then names them together
instead of ranking one above the other by nothing.

Known reasons (:data:`KNOWN_REASONS`) are keyed by the set of registry names involved; the text
states the cause and how it was measured. Without a known reason the report says only what it
measured: the same scores and pixels, cause not known to the report.

Pitfalls
--------
* Equal scores with unequal pixels are not identical (a metric can tie by chance on a tiny frame):
  where both labels kept an image of the same frame, the pixels decide.
* A label with failed units is never identical to another: its missing frames are not a match.
"""

from __future__ import annotations

from dataclasses import dataclass

from denoisebench.results.names import NOISY

#: Why registry names give the same output, by the set of names.
KNOWN_REASONS = {
    frozenset({"oidn", "oidn_balanced"}): (
        "OIDN (pyoidn 2.5.1, OIDN 2.5.1) runs the same network for both: with noisy albedo and normal "
        "(cleanAux off) the RT filter's HDR model has only its base weights (rt_hdr_alb_nrm; a larger "
        "high-quality model exists only for prefiltered, clean auxiliary images), high and balanced both "
        "select them, and balanced's fast math changes nothing on a CPU device. Measured: bit-identical "
        "outputs at 64×64 and 256×256, with and without albedo and normal; oidn_fast uses smaller weights "
        "and differs."
    ),
}


@dataclass(frozen=True, kw_only=True)
class IdenticalGroup:
    """Labels whose every score and kept image agree; ``reason``: why, or None when not known."""

    labels: list[str]
    frames: int
    images: int
    """Kept images compared pixel by pixel (all equal)."""
    reason: str | None

    def sentence(self) -> str:
        names = " and ".join(self.labels) if len(self.labels) == 2 else ", ".join(self.labels)
        measured = f"every score of {self.frames} frame(s) agrees in every digit" + (
            f" and {self.images} kept image(s) are the same pixels" if self.images else ""
        )
        why = self.reason or "the report does not know why (the same code path, or the same weights)"
        return f"{names} are identical in this run ({measured}): {why}"


def _fingerprint(frames, sequences, label: str):
    rows = sorted(
        (f.scene, f.spp, f.frame, f.status, tuple(sorted((k, v) for k, v in f.metrics.items())))
        for f in frames
        if f.denoiser == label
    )
    seq = sorted((s.scene, s.spp, s.metric, s.value) for s in sequences if s.denoiser == label)
    if not rows or any(r[3] != "ok" for r in rows):
        return None
    return tuple(rows), tuple(seq)


def _registry_name(entry) -> str:
    """The registry name a label runs (its spec when that is a plain name, else the label)."""
    spec = getattr(entry, "spec", None) or getattr(entry, "label", "")
    return spec if spec.isidentifier() else getattr(entry, "label", spec)


def identical_groups(frames, sequences, entries, *, same_pixels=None) -> list[IdenticalGroup]:
    """Groups of labels (noisy input left out) with the same fingerprint of scores.

    ``frames``/``sequences``: the run's FrameRow/SequenceRow; ``entries``: its EntryRow (for the
    registry names); ``same_pixels(a, b)``: (images compared, all equal) of the kept images of two
    labels, or None to skip the pixel check."""
    by_print: dict = {}
    order = [e.label for e in entries if not e.load_error and e.label != NOISY]
    for label in order:
        found = _fingerprint(frames, sequences, label)
        if found is not None:
            by_print.setdefault(found, []).append(label)
    names = {e.label: _registry_name(e) for e in entries}
    groups = []
    for printed, labels in by_print.items():
        if len(labels) < 2:
            continue
        images = 0
        if same_pixels is not None:
            checks = [same_pixels(labels[0], other) for other in labels[1:]]
            if not all(equal for _, equal in checks):
                continue
            images = sum(count for count, _ in checks)
        reason = KNOWN_REASONS.get(frozenset(names[label] for label in labels))
        groups.append(IdenticalGroup(labels=labels, frames=len(printed[0]), images=images, reason=reason))
    return groups
