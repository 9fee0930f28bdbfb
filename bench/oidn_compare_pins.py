"""OIDN's own comparison code on fixed frames: the pinned values of ``tests/metrics/field/test_oidn.py``.

    OIDN_TRAINING=/path/to/oidn/training [OIDN_COMMIT=<hash>] .venv/bin/python bench/oidn_compare_pins.py

``OIDN_TRAINING`` is the ``training/`` folder of an Open Image Denoise checkout
(https://github.com/RenderKit/oidn; e.g. ``git archive HEAD training | tar -x``); its scripts
need torch and OpenImageIO, both in the project's venv. The script writes each of
:func:`pin_frames`' prediction/reference pairs as float32 EXRs (OpenImageIO, as their
``save_image``) and scores them twice with OIDN's code, each in a subprocess (their modules are
called ``color``, ``image``, ``util``: kept out of this process):

1. their evaluation path at full precision: ``dataset.load_image_features(name, ['hdr'])`` (EXR
   read, clamped at 0), ``image_to_tensor``, ``transform_feature(..., 'hdr', 'srgb', 1.)`` and
   ``image.compare_images(..., 'psnr' | 'ssim')``;
2. ``compare_image.py pred.hdr.exr ref.hdr.exr`` itself, whose printed 4-decimal line is parsed.

It prints both beside ours (:mod:`denoisebench.metrics.field.oidn_compare`) and the largest
differences, then the ``PINS`` dictionary to paste into the test (OIDN's full-precision values).

Notes
-----
The ``negative`` frame has negative prediction pixels: ``compare_image.py`` scores it without
clamping (its Hable curve is not monotone below 0) and differs from path 1 and from ours, which
clamp at 0 as OIDN's ``infer.py`` and dataset loader do; it is printed, not compared.
``compare_image.py`` raises ZeroDivisionError on identical images, so no frame pair is equal.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HEIGHT, WIDTH = 36, 44

#: Runs in OIDN's training folder: their loader, transfer and metrics on the pairs named in argv.
_THEIR_EVALUATION = """
import json, sys
from dataset import load_image_features, transform_feature
from image import image_to_tensor, compare_images
out = {}
for name in sys.argv[2:]:
    pair = []
    for role in ("pred", "ref"):
        image, _ = load_image_features(sys.argv[1] + "/" + role + "_" + name, ["hdr"])
        pair.append(transform_feature(image_to_tensor(image, batch=True), "hdr", "srgb", 1.0))
    out[name] = {"psnr": float(compare_images(*pair, "psnr")), "ssim": float(compare_images(*pair, "ssim"))}
print(json.dumps(out))
"""


def pin_frames() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Deterministic (pred, ref) float32 HDR pairs, 36×44×3, by case name.

    ``noisy``: a smooth colour field in [0.1, 3] with Gaussian noise (σ 0.15), clamped at 0;
    ``dark``: the field scaled to 1e-3 with 30 % relative noise (the curve's linear toe and the
    sRGB linear segment); ``bright``: the field scaled to [2, 60] (most pixels past the white
    point 6.37) with 20 % noise; ``fireflies``: ``noisy`` with 12 pixels set to 1e2–1e6;
    ``blurred``: a textured reference and its 5×5 box blur (structure lost, little noise);
    ``negative``: ``noisy`` minus 0.2 (negative pixels, clamped by the metric).
    """
    rng = np.random.default_rng(20260102)
    y, x = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float64)
    y, x = y / HEIGHT, x / WIDTH
    field = np.stack(
        [
            0.1 + 2.9 * x * (0.5 + 0.5 * np.sin(5 * y)),
            0.1 + 1.5 * (1 + np.cos(4 * x + 2 * y)) / 2 + 0.2,
            0.4 + 2 * y * x,
        ],
        axis=-1,
    )
    noisy = np.maximum(field + 0.15 * rng.standard_normal(field.shape), 0.0)
    frames = {"noisy": (noisy, field)}
    dark = 1e-3 * field
    frames["dark"] = (np.maximum(dark * (1 + 0.3 * rng.standard_normal(field.shape)), 0.0), dark)
    bright = 2.0 + 58.0 * (field - field.min()) / (field.max() - field.min())
    frames["bright"] = (np.maximum(bright * (1 + 0.2 * rng.standard_normal(field.shape)), 0.0), bright)
    fire = noisy.copy()
    idx = rng.choice(HEIGHT * WIDTH, size=12, replace=False)
    fire.reshape(-1, 3)[idx] = 10.0 ** rng.uniform(2, 6, size=(12, 1))
    frames["fireflies"] = (fire, field)
    texture = field * (1 + 0.8 * (rng.random(field.shape[:2])[..., None] > 0.5))
    padded = np.pad(texture, ((2, 2), (2, 2), (0, 0)), mode="edge")
    blurred = sum(padded[i : i + HEIGHT, j : j + WIDTH] for i in range(5) for j in range(5)) / 25.0
    frames["blurred"] = (blurred, texture)
    frames["negative"] = (noisy - 0.2, field)
    return {k: (p.astype(np.float32), r.astype(np.float32)) for k, (p, r) in frames.items()}


def _write_exr(path: Path, image: np.ndarray) -> None:
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(str(path))
    spec = oiio.ImageSpec(image.shape[1], image.shape[0], 3, oiio.FLOAT)
    spec.attribute("compression", "piz")
    if not out.open(str(path), spec) or not out.write_image(np.ascontiguousarray(image, dtype=np.float32)):
        raise RuntimeError(f"could not write {path}: {out.geterror()}")
    out.close()


def write_frames(folder: Path, frames: dict) -> None:
    """``pred_<name>.hdr.exr`` and ``ref_<name>.hdr.exr`` for every pair (their ``hdr`` feature suffix)."""
    for name, (pred, ref) in frames.items():
        _write_exr(folder / f"pred_{name}.hdr.exr", pred)
        _write_exr(folder / f"ref_{name}.hdr.exr", ref)


def _run_oidn(training: Path, args: list[str], cwd: Path, what: str) -> str:
    """stdout of ``python ARGS`` run in ``cwd`` with OIDN's ``training/`` importable; a failure raises with its stderr."""
    proc = subprocess.run(
        [sys.executable, *args],
        cwd=cwd,
        env={**os.environ, "PYTHONPATH": str(training)},
        capture_output=True,
        text=True,
        timeout=600,
    )
    if proc.returncode:
        raise RuntimeError(f"{what} failed:\n{proc.stderr[-2000:]}")
    return proc.stdout


def their_evaluation(training: Path, folder: Path, names) -> dict[str, dict[str, float]]:
    """OIDN's loader + transfer + ``compare_images`` (path 1 of the module docstring), full precision."""
    out = _run_oidn(training, ["-c", _THEIR_EVALUATION, str(folder), *names], training, "OIDN evaluation")
    return json.loads(out.strip().splitlines()[-1])


def their_compare_image(training: Path, folder: Path, name: str) -> dict[str, float]:
    """``compare_image.py pred ref`` (path 2): the values of the line it prints (4 decimals)."""
    args = [str(training / "compare_image.py"), f"pred_{name}.hdr.exr", f"ref_{name}.hdr.exr"]
    out = _run_oidn(training, args, folder, f"compare_image.py on {name}")
    return {k: float(v) for k, v in re.findall(r"(\w+) = ([-+0-9.eEnaif]+)", out)}


def oidn_commit(training: Path) -> str:
    """``OIDN_COMMIT`` when set (a ``git archive`` extract has no history), else the work tree's commit."""
    if os.environ.get("OIDN_COMMIT"):
        return os.environ["OIDN_COMMIT"]
    proc = subprocess.run(["git", "-C", str(training), "rev-parse", "HEAD"], capture_output=True, text=True)
    return proc.stdout.strip() if proc.returncode == 0 else "unknown"


def main() -> int:
    from denoisebench.metrics.field.oidn_compare import oidn_psnr, oidn_ssim

    training = os.environ.get("OIDN_TRAINING")
    if not training or not (Path(training) / "compare_image.py").is_file():
        print("set OIDN_TRAINING to an OIDN training/ folder (with compare_image.py)", file=sys.stderr)
        return 2
    training = Path(training).resolve()
    frames = pin_frames()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        write_frames(folder, frames)
        theirs = their_evaluation(training, folder, list(frames))
        printed = {name: their_compare_image(training, folder, name) for name in frames}
    print(f"OIDN training folder {training} (commit {oidn_commit(training)}), frames {HEIGHT}x{WIDTH}")
    print(
        f"{'frame':10} {'theirs psnr':>14} {'ours psnr':>14} {'printed':>9} {'theirs ssim':>12} {'ours ssim':>12} {'printed':>8}"
    )
    worst_psnr = worst_ssim = 0.0
    for name, (pred, ref) in frames.items():
        op, os_ = oidn_psnr(pred, ref), oidn_ssim(pred, ref)
        t, pr = theirs[name], printed[name]
        print(
            f"{name:10} {t['psnr']:14.8f} {op:14.8f} {pr['psnr']:9.4f} {t['ssim']:12.9f} {os_:12.9f} {pr['ssim']:8.4f}"
        )
        worst_psnr = max(worst_psnr, abs(op - t["psnr"]))
        worst_ssim = max(worst_ssim, abs(os_ - t["ssim"]))
    print(f"largest |ours - theirs|: {worst_psnr:.3g} dB (PSNR), {worst_ssim:.3g} (SSIM)")
    print("PINS = {")
    for name in frames:
        print(f'    "{name}": ({theirs[name]["psnr"]!r}, {theirs[name]["ssim"]!r}),')
    print("}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
