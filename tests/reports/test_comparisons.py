"""Image comparisons show every input spp, and the frame that decides a scene's mean where one does.

A denoiser that blows up one frame of eight (OIDN smearing a small bright emitter) is left out of its
scene's trimmed mean; the report must still let the reader look at that frame, at each spp.
"""

from __future__ import annotations

import textwrap

import pytest

from denoisebench.benchmark.run import run_benchmark
from denoisebench.benchmark.runner import BenchmarkConfig
from denoisebench.dataset import open_dataset
from denoisebench.dataset.synthetic import make_synthetic_dataset
from denoisebench.reports.build import build_report, write_report
from denoisebench.results.store import ResultsStore

BLOWN = 5


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    root = tmp_path_factory.mktemp("comparisons")
    plugin = root / "blows.py"
    plugin.write_text(
        textwrap.dedent(
            f"""
            import numpy as np

            class Blows:
                '''The input as it is, but frame {BLOWN} a thousand times brighter.'''

                def denoise(self, frame):
                    out = np.array(frame.color, dtype=np.float32)
                    return out * 1000.0 if frame.index == {BLOWN} else out
            """
        )
    )
    data = open_dataset(make_synthetic_dataset(root / "ds", scenes=1, frames=8, height=16, width=16, spp=(1, 4)))
    config = BenchmarkConfig(
        denoisers=["identity", f"{plugin}:Blows"], spp=[1, 4], split="all", metrics=["relmse", "flip"], isolation="none"
    )
    with ResultsStore(root / "r.sqlite") as store:
        plan = run_benchmark(data, config, store, progress=False)
        report = build_report(store, plan.run_id, data)
        write_report(store, plan.run_id, data, root / "report")
    return root, report


def test_every_spp_has_a_comparison_and_each_deciding_frame_one_of_its_own(run):
    root, report = run
    last = [c for c in report.comparisons if not c.why]
    assert sorted(c.spp for c in last) == [1, 4] and {c.frame for c in last} == {7}
    deciding = [c for c in report.comparisons if c.why]
    assert sorted(c.spp for c in deciding) == [1, 4], [c.why for c in deciding]
    for comp in deciding:
        assert comp.frame == BLOWN and "Blows" in comp.why and "relmse_robust" in comp.why
        kinds = [e.kind for e in comp.entries]
        assert kinds[0] == "input" and kinds[-1] == "reference" and "denoiser" in kinds
        blown = [e for e in comp.entries if "Blows" in e.label]
        assert blown and blown[0].relmse > 100  # the frame shown is the blown one
    # the trimmed mean leaves the blown frame out: the plugin scores about like the input it returns
    # (one more of the input's own frames is kept in place of the blown one)
    rows = {(r.denoiser, r.spp): r for r in report.summary}
    for spp in (1, 4):
        plugin = next(v for (label, s), v in rows.items() if s == spp and "Blows" in label)
        identity = rows[("identity", spp)].metrics["relmse_robust"].value
        assert plugin.metrics["relmse_robust"].value == pytest.approx(identity, rel=0.1)  # not ×1e6
    html = (root / "report" / "index.html").read_text()
    assert html.count("Decides a mean:") == 2
    markdown = (root / "report" / "report.md").read_text()
    assert f"frame {BLOWN}, 1 spp:" in markdown and f"frame {BLOWN}, 4 spp:" in markdown
