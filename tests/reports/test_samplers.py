"""The report's sampler part end to end: a live run (16×16 px, 2 frames) with ``uniform`` and a plugin that
leaves the right half of every frame without a sample; cvvdp measured, so its viewing conditions show.

The plugin's counts are known exactly (all of a frame's budget in its left half), so the report's numbers
are checked against them, not against themselves.
"""

from __future__ import annotations

import base64
import io
import json
import textwrap

import numpy as np
import pytest

from denoisebench.cli import main
from denoisebench.reports import images

SIZE, FRAMES, SPP = 16, 2, 2

LEFT_HALF = textwrap.dedent(
    """
    import numpy as np

    from denoisebench.sampling.allocation import allocate


    class LeftHalf:
        name = "left_half"

        def sample(self, budget, rounds):
            weights = np.zeros((rounds.height, rounds.width))
            weights[:, : rounds.width // 2] = 1.0
            rounds.render(allocate(weights, rounds.remaining_samples()))
    """
)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    root = tmp_path_factory.mktemp("samplers")
    plugin = root / "left_half.py"
    plugin.write_text(LEFT_HALF)
    data = root / "ds"
    size = ["--width", str(SIZE), "--height", str(SIZE)]
    args = ["--families", "cornell", "--scenes", "1", "--frames", str(FRAMES), *size, "--spp", str(SPP)]
    assert main(["generate", "--out", str(data), *args, "--ref-spp", "32", "--seed", "5", "--quiet"]) == 0
    spec = f"{plugin}:LeftHalf"
    code = main(
        [
            "benchmark",
            "--time-size",
            "64x64",
            "--data",
            str(data),
            "--db",
            str(root / "db.sqlite"),
            "--out",
            str(root / "report"),
            "--denoisers",
            "identity",
            "--samplers",
            f"uniform,{spec}",
            "--split",
            "all",
            "--metrics",
            "relmse,cvvdp",
            "--no-verify",
        ]
    )
    assert code == 0
    return root / "report", spec


def _png(uri_or_bytes) -> np.ndarray:
    from PIL import Image

    raw = uri_or_bytes
    if isinstance(raw, str):
        raw = base64.b64decode(raw.split(",", 1)[1])
    return np.asarray(Image.open(io.BytesIO(raw)).convert("RGB"))


def test_results_json_counts_the_plugins_unsampled_half(run):
    report, spec = run
    results = json.loads((report / "results.json").read_text())
    samplers = results["samplers"]
    assert samplers["samplers"] == ["uniform", spec]
    frames = {(f["sampler"], f["frame"]): f for f in samplers["frames"]}
    assert len(frames) == 2 * FRAMES  # the samplers alone; their pairs share the render
    for t in range(FRAMES):
        half = frames[(spec, t)]
        assert half["pixels_without_samples"] == SIZE * SIZE // 2
        assert half["samples"] == SPP * SIZE * SIZE and half["max_spp"] == 2 * SPP
        assert frames[("uniform", t)]["pixels_without_samples"] == 0 and frames[("uniform", t)]["max_spp"] == SPP
    (row,) = samplers["undersampled"]
    assert (row["sampler"], row["spp"], row["frames_affected"], row["pixels_max"]) == (spec, SPP, FRAMES, 128)
    assert row["pixels_total"] == FRAMES * 128
    assert samplers["map_scale"] == [{"scene": row["scene"], "spp": SPP, "top": 2 * SPP}]


def test_the_warning_is_in_report_md_and_index_html(run):
    report, spec = run
    md, page = (report / "report.md").read_text(), (report / "index.html").read_text()
    assert "Pixels without a sample" in md and "Pixels without a sample" in page
    assert "left pixels with fewer than 1 sample in" in md
    warning = next(line for line in md.splitlines() if "left pixels with fewer than 1 sample" in line)
    assert f"{FRAMES} of {FRAMES} frame(s), up to 128 pixel(s) per frame" in warning
    assert "uniform left pixels" not in md and "uniform left pixels" not in page  # uniform fills every pixel


def test_each_samplers_spp_map_is_beside_its_image_on_the_shared_scale(run):
    report, spec = run
    md = (report / "report.md").read_text()
    samplers = md[md.index("## Samplers") :]
    rows = [line for line in samplers.splitlines() if line.startswith("| ") and "spp_maps/" in line]
    assert len(rows) == 2  # uniform and the plugin, each with its image and its map
    half_map = _png((report / "figures/spp_maps").joinpath(rows[1].split("spp_maps/")[2].split(")")[0]).read_bytes())
    uniform_map = _png((report / "figures/spp_maps").joinpath(rows[0].split("spp_maps/")[2].split(")")[0]).read_bytes())
    scale = half_map.shape[0] // SIZE
    half_map, uniform_map = half_map[::scale, ::scale], uniform_map[::scale, ::scale]
    # the plugin's right half has no sample (red); its left half has 2×SPP, the scale's top (viridis yellow)
    assert (half_map[:, SIZE // 2 :] == images.NO_SAMPLE_RGB).all()
    top = _png(images.spp_map_png(np.full((1, 1), 2 * SPP), 2 * SPP))[0, 0]
    assert (half_map[:, : SIZE // 2] == top).all()
    # uniform's SPP samples sit at half the scale: one colour, darker than the top, not red
    assert (uniform_map == uniform_map[0, 0]).all() and uniform_map[0, 0].sum() < top.sum()
    assert "0–4 spp" in rows[0] and "| 128 |" in rows[1]
    page = (report / "index.html").read_text()
    assert page.count('class="tile sppmap"') == 2 and f"spp map of {spec}" in page
    assert page.index(f'alt="{spec}"') < page.index(f'alt="spp map of {spec}"')  # the map follows its image


def test_cvvdp_viewing_conditions_are_stated(run):
    report, _ = run
    results = json.loads((report / "results.json").read_text())
    viewing = results["cvvdp_viewing"]
    assert viewing["display"]["display"] == "standard_hdr_linear" and viewing["display"]["ppd"] == pytest.approx(75.4)
    (scene,) = viewing["scenes"].values()
    assert scene["frame_px"] == [SIZE, SIZE] and scene["field_deg"][0] == pytest.approx(SIZE / 75.4)
    assert scene["exposure"] > 0
    md, page = (report / "report.md").read_text(), (report / "index.html").read_text()
    for text in (md, page):
        assert "cvvdp viewing conditions" in text and "75.4 pixels per degree" in text
        assert f"{SIZE / 75.4:.2f}°×{SIZE / 75.4:.2f}°" in text


def test_sampler_frames_round_trip_through_the_store_and_an_old_store_reads_as_none(tmp_path):
    import sqlite3

    from denoisebench.results import sampler_maps
    from denoisebench.results.records import FrameRecord, UnitRecord
    from denoisebench.results.store import ResultsStore

    rng = np.random.default_rng(3)
    maps = [(t, rng.integers(0, 5, size=(6, 7)).astype(np.int32)) for t in range(3)]
    frames = sampler_maps.frame_records(maps)
    assert [f.spp is None for f in frames] == [True, True, False]  # only the image frame keeps its map
    assert [f.pixels_without_samples for f in frames] == [int((m < 1).sum()) for _, m in maps]
    unit = UnitRecord(
        denoiser="s",
        scene="scene",
        spp=4,
        status="ok",
        error=None,
        frames=[
            FrameRecord(frame=t, status="ok", error=None, render_seconds=1.0, denoise_seconds=0.0, total_seconds=1.0)
            for t in range(3)
        ],
    )
    unit.sampler_frames = frames
    with ResultsStore(tmp_path / "r.sqlite") as store:
        store.ensure_run("run", dataset_hash="hash", dataset_path="/data", config={"denoisers": []}, versions={})
        assert store.write_unit("run", unit)
        rows = sampler_maps.read(store, "run")
        assert store.integrity_problems() == []
        # a unit row deleted by hand leaves its spp maps behind: the integrity check names them
        store.conn.execute("DELETE FROM units")
        store.conn.commit()
        assert f"3 row(s) of {sampler_maps.TABLE} without a unit" in store.integrity_problems()
    assert [r.frame for r in rows] == [0, 1, 2] and [r.samples for r in rows] == [int(m.sum()) for _, m in maps]
    np.testing.assert_array_equal(rows[2].spp_map, maps[2][1])
    assert rows[0].spp_map is None and rows[2].max_spp == int(maps[2][1].max())
    # a database written before the table existed, opened read-only, has no sampler frames
    conn = sqlite3.connect(tmp_path / "r.sqlite")
    conn.execute(f"DROP TABLE {sampler_maps.TABLE}")
    conn.commit()
    conn.close()
    with ResultsStore(tmp_path / "r.sqlite", readonly=True) as store:
        assert sampler_maps.read(store, "run") == []
