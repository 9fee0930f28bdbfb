"""Samplers in a benchmark run: sampler × denoiser pairs rendered live on the dataset's own scenes.

``run-benchmark --samplers uniform,ci_stop,...`` adds, for every sampler, the pair ``SAMPLER`` (its
image as it is) and ``SAMPLER+DENOISER`` for every denoiser of the run. A pair is measured like a
denoiser, unit by unit (scene × spp): each frame of the scene's sequence is rendered live by the
sampler at that spp as its mean budget (:mod:`denoisebench.sampling.live`: the scene's own stage,
plan and size, a seed disjoint from the stored inputs' and the reference's, the same seed for every
sampler), the denoiser gets those buffers in place of the stored input, and the output is scored
against the dataset's reference with the run's metrics (:func:`~.measure.measure_unit`). The frame's
render seconds are the sampler's (render + decision), so the pairs are curves of their own in the
accuracy-vs-time figure and rows in the equal-time tables.

Notes
-----
* One live render per sampler, frame and spp feeds all of that sampler's pairs: its denoisers see
  the same image.
* A sampler that fails (raises, or the renderer refuses its round) fails its pairs' units with the
  reason; a sampler that leaves pixels with fewer than 1 sample is warned about on stderr (their
  value is 0, not an estimate), and every unit keeps its frames' spp maps and counts
  (:mod:`.sampler_maps`), so that the report shows them.
* Each pair is registered with its place in the run's sampler dimension (the store's
  ``run_denoisers.sampler`` and ``denoiser_label``, :class:`~.records.EntryRow`), so the
  analyses rank and group by sampler without parsing labels.
* Plugin samplers run in a worker of their own under the run's ``--isolation``, ``--time-limit`` and
  ``--memory-limit`` (:mod:`denoisebench.sampling.isolation`); built-ins in this process.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, replace

import numpy as np

from denoisebench.benchmark.measure import measure_unit
from denoisebench.dataset.frame import Frame
from denoisebench.errors import UserInputError
from denoisebench.results.names import PAIR_LABEL_SEPARATOR, PAIR_SPEC_SEPARATOR, SAMPLER_SPEC_PREFIX
from denoisebench.results.records import UnitRecord
from denoisebench.results.sampler_maps import frame_records
from denoisebench.sampling.isolation import IsolatedSampler, load, sampler_policy
from denoisebench.sampling.live import LiveScene, run_live
from denoisebench.sampling.protocol import Budget

SEPARATOR = PAIR_LABEL_SEPARATOR  # between a pair's sampler and denoiser labels


@dataclass(frozen=True, kw_only=True)
class SamplerPair:
    """A sampler and the denoiser its buffers go to (None: none); ``label`` names the pair in the store."""

    label: str
    sampler: str
    denoiser: str | None
    isolation: str = "plugins"  # sampling.isolation policy
    time_limit: float | None = None
    memory_limit_mb: int | None = None

    def load(self):

        return load(
            self.sampler, policy=self.isolation, time_limit=self.time_limit, memory_limit_mb=self.memory_limit_mb
        )


def plan_pairs(
    sampler_specs: list[str], denoisers, taken: set[str], *, isolation: str = "plugins", limits=None
) -> list[SamplerPair]:
    """Every sampler alone and with every loaded denoiser; each sampler is loaded once to fail early (exit 2).

    ``isolation`` is the run's (denoisers') policy, mapped by :func:`~denoisebench.sampling.isolation.sampler_policy`;
    ``limits`` its :class:`~denoisebench.denoisers.isolation.Limits` (time and memory of a plugin sampler's worker).
    """
    policy = sampler_policy(isolation)
    time_limit = getattr(limits, "time_limit", None)
    memory = getattr(limits, "memory_limit_mb", None)
    pairs = []
    for spec in dict.fromkeys(s.strip() for s in sampler_specs if s.strip()):
        if spec in taken:
            raise UserInputError(f"sampler {spec!r} has the label of a denoiser of this run")
        alone = SamplerPair(
            label=spec, sampler=spec, denoiser=None, isolation=policy, time_limit=time_limit, memory_limit_mb=memory
        )
        _close(alone.load())  # UnknownSamplerError / SamplerLoadError: one line, before any work
        pairs.append(alone)
        pairs.extend(
            replace(alone, label=f"{spec}{SEPARATOR}{d.label}", denoiser=d.label)
            for d in denoisers
            if d.instance is not None
        )
    return pairs


def _close(sampler) -> None:

    if isinstance(sampler, IsolatedSampler):
        sampler.close()


def register_pairs(store, run_id: str, pairs: list[SamplerPair], denoisers) -> None:
    by_label = {d.label: d for d in denoisers}
    for pair in pairs:
        denoiser = by_label.get(pair.denoiser) if pair.denoiser else None
        spec = f"{SAMPLER_SPEC_PREFIX}{pair.sampler}" + (f"{PAIR_SPEC_SEPARATOR}{denoiser.spec}" if denoiser else "")
        needs = denoiser.needs if denoiser else {"color"}
        store.add_denoiser(
            run_id=run_id,
            label=pair.label,
            spec=spec,
            kind="sampler",
            needs=needs,
            temporal=bool(denoiser and denoiser.temporal),
            load_error=None,
            sampler=pair.sampler,
            denoiser_label=pair.denoiser,
        )


def live_sequence(dataset, scene: str, spp: int, pair: SamplerPair, live=None, maps: list | None = None):
    """(the scene's sequence at ``spp`` with every frame rendered live by the sampler, None) or (None, reason).

    ``maps``: a list to append (frame index, H×W spp map) of every frame to (the report shows them)."""
    sampler_spec = pair.sampler
    stored = dataset.sequence(scene, spp, samples=False)
    live = live or LiveScene.from_dataset(dataset, scene)
    frames = []
    for frame in stored:
        sampler = pair.load()
        try:
            result = run_live(sampler, live, frame.index, budget=Budget(spp=spp))
        finally:
            _close(sampler)
        if result.error:
            return None, f"sampler {sampler_spec}: {result.error}"
        if result.pixels_without_samples:
            print(
                f"warning: sampler {sampler_spec} left {result.pixels_without_samples} pixel(s) without a sample "
                f"in {scene} frame {frame.index} at {spp} spp (their value is 0)",
                file=sys.stderr,
            )
        meta = {**frame.meta, "seconds": result.seconds, "sampler": result.summary()}
        if maps is not None:
            maps.append((frame.index, result.spp))
        buffers = {name: np.ascontiguousarray(value, dtype=np.float32) for name, value in result.buffers.items()}
        frames.append(
            Frame(buffers=buffers, spp=int(spp), scene=scene, index=frame.index, reference=frame.reference, meta=meta)
        )
    return replace(stored, frames=frames), None


def measure_pairs(dataset, plan, scene: str, spp: int, pairs: list[SamplerPair], instances: dict):
    """Yield the UnitRecord of every pair on ``scene`` at ``spp`` (one live render per sampler)."""

    by_sampler: dict[str, list[SamplerPair]] = {}
    for pair in pairs:
        by_sampler.setdefault(pair.sampler, []).append(pair)
    for sampler, group in by_sampler.items():
        maps: list = []
        sequence, error = live_sequence(dataset, scene, spp, pair=group[0], maps=maps)
        for pair in group:
            if sequence is None:
                yield UnitRecord(denoiser=pair.label, scene=scene, spp=spp, status="failed", error=error, frames=[])
                continue
            denoiser = instances.get(pair.denoiser) if pair.denoiser else None
            unit = measure_unit(
                pair.label, denoiser, sequence, spatial=plan.spatial, temporal=plan.temporal, trim=plan.trim
            )
            unit.sampler_frames = frame_records(maps)  # spp maps and empty pixels, for the report
            yield unit
