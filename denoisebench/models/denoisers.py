"""The learned models as Denoisers (built-ins ``dpcn``, ``kpcn``, ``rae``, ``lbf``).

Each loads the shipped small weights (``denoisebench/models/weights/<name>_small.pt``, see the
model card beside it) unless given ``checkpoint=PATH`` (``--option checkpoint=PATH`` on the
command line), a file written by ``denoisebench train``. Inference is CPU torch under
``no_grad`` with ``threads`` intra-op threads (default 1: on a shared 2-core machine more threads
spin against each other).

Notes
-----
* DPCN/KPCN run in tiles (``tile`` pixels plus a halo as wide as the network's receptive field),
  so KPCN's 441 kernel weights per pixel never exist for more than one tile at a time. With the
  halo, tiled and whole-frame outputs agree (tested).
* The recurrent autoencoder keeps its hidden state between ``denoise`` calls (``temporal = True``);
  the harness calls :meth:`reset` between sequences. It runs on whole frames: its U-Net sees far,
  and a tiled recurrent state would need per-tile memories.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from denoisebench.dataset.frame import Frame
from denoisebench.denoisers.protocol import DenoiserBase
from denoisebench.denoisers.registry import DenoiserUnavailableError
from denoisebench.models.checkpoint import load_checkpoint, model_from_checkpoint
from denoisebench.models.features import FRAME_SCALARS, exposure, frame_tensors, to_image
from denoisebench.models.provenance import all_train_scenes

WEIGHTS_DIR = Path(__file__).parent / "weights"


def shipped_weights(model: str) -> Path:
    """Path of the shipped small weights of ``model``."""
    return WEIGHTS_DIR / f"{model}_small.pt"


class LearnedDenoiser(DenoiserBase):
    """Base: load a checkpoint of ``model_name`` and run it on frames."""

    model_name = ""

    def __init__(self, checkpoint: str | None = None, threads: int = 1):
        path = Path(checkpoint) if checkpoint else shipped_weights(self.model_name)
        if checkpoint is None and not path.is_file():
            raise DenoiserUnavailableError(f"{self.model_name}: shipped weights {path} are missing")
        payload = load_checkpoint(path, expect_model=self.model_name)
        self.checkpoint = str(path)
        self.meta = payload["meta"]
        #: every run's train scenes (fine-tuned weights: the earlier runs' too); the benchmark marks them
        self.trained_scenes = frozenset(all_train_scenes(self.meta))
        self.config = payload["config"]
        self.model = model_from_checkpoint(payload).eval()
        self.threads = max(1, int(threads))

    def _run(self, tensors: dict[str, torch.Tensor]) -> torch.Tensor:
        return self.model(tensors)["color"]

    def denoise(self, frame: Frame) -> np.ndarray:
        previous = torch.get_num_threads()
        torch.set_num_threads(self.threads)
        try:
            with torch.no_grad():
                return to_image(self._run(frame_tensors(frame)))
        finally:
            torch.set_num_threads(previous)


class PCNDenoiser(LearnedDenoiser):
    """DPCN/KPCN: spatial, tiled."""

    needs = frozenset({"color", "albedo", "normal", "depth"})

    def __init__(self, checkpoint: str | None = None, threads: int = 1, tile: int = 256):
        super().__init__(checkpoint, threads)
        self.model.return_kernels = False
        # tiles bound memory (KPCN holds 2·441 kernel planes per pixel: ~0.7 GB at 300² with the halo);
        # each tile recomputes a halo, 1.4× the pixels at 256 (1.8× at 128)
        self.tile = max(8, int(tile))
        cfg = self.config
        # Receptive radius: each conv adds kernel//2, the input gradients 1, the firefly clamp 1, and
        # KPCN's applied kernel size//2 (it reads noisy pixels that far away).
        applied = cfg.get("kernel_size", 1) // 2 if self.model.mode == "kernel" else 0
        head = cfg.get("head_kernel") or cfg["kernel"]
        self.halo = (cfg["layers"] - 1) * (cfg["kernel"] // 2) + head // 2 + 2 + applied

    def _run(self, tensors: dict[str, torch.Tensor]) -> torch.Tensor:
        height, width = tensors["color"].shape[-2:]
        tensors = {**tensors, "exposure": exposure(tensors["color"])}  # one scale for every tile
        if height <= self.tile and width <= self.tile:
            return self.model(tensors)["color"]
        out = torch.empty_like(tensors["color"])
        for top in range(0, height, self.tile):
            for left in range(0, width, self.tile):
                y0, x0 = max(0, top - self.halo), max(0, left - self.halo)
                y1, x1 = min(height, top + self.tile + self.halo), min(width, left + self.tile + self.halo)
                tile = {k: v if k in FRAME_SCALARS else v[..., y0:y1, x0:x1] for k, v in tensors.items()}
                part = self.model(tile)["color"]
                rows, cols = min(self.tile, height - top), min(self.tile, width - left)
                out[..., top : top + rows, left : left + cols] = part[
                    ..., top - y0 : top - y0 + rows, left - x0 : left - x0 + cols
                ]
        return out


class DPCN(PCNDenoiser):
    """Direct-prediction network (Bako et al. 2017)."""

    name = "dpcn"
    model_name = "dpcn"


class KPCN(PCNDenoiser):
    """Kernel-predicting network, 21×21 softmax kernels (Bako et al. 2017)."""

    name = "kpcn"
    model_name = "kpcn"


class RAE(LearnedDenoiser):
    """Recurrent denoising autoencoder (Chaitanya et al. 2017); temporal."""

    name = "rae"
    model_name = "rae"
    temporal = True
    needs = frozenset({"color", "normal", "depth", "roughness"})

    def __init__(self, checkpoint: str | None = None, threads: int = 1):
        super().__init__(checkpoint, threads)
        if self.model.demodulate:
            self.needs = self.needs | {"albedo"}
        if self.model.view_normals:  # the camera's axes come from the position buffer
            self.needs = self.needs | {"position"}

    def reset(self) -> None:
        self.model.reset()


class LBFDenoiser(LearnedDenoiser):
    """The MLP-predicted cross-bilateral filter (Kalantari et al. 2015); spatial, whole frames.

    The filter runs as shifted views with two accumulators, so a whole frame needs only a few
    image-sized buffers: no tiling.
    """

    name = "lbf"
    model_name = "lbf"
    needs = frozenset({"color", "albedo", "normal", "depth"})
