"""In-memory frames and sequences: what readers yield and denoisers receive (torch-free).

Buffers follow docs/architecture.md's table: ``Frame.buffers["color"]`` is H×W×3 float32 linear radiance,
``"albedo"``, ``"normal"``, ``"depth"`` (H×W×1) and so on, ``"<name>_var"`` the per-pixel variance of
the mean. Per-sample data, when present, is ``Frame.samples``: a mapping of buffer name to
S×H×W×C arrays (S samples per pixel), including the random parameters ``pixel`` (2 channels),
``lens`` (2, depth of field only) and ``time`` (1, motion blur only).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field

import numpy as np

#: Channel count of every buffer docs/architecture.md names (variances have their base buffer's count).
BUFFER_CHANNELS: dict[str, int] = {
    "color": 3,
    "diffuse": 3,
    "specular": 3,
    "albedo": 3,
    "normal": 3,
    "depth": 1,
    "position": 3,
    "roughness": 1,
    "motion": 2,
}


def expected_channels(name: str) -> int | None:
    """Channels of buffer ``name`` (``color_var`` has color's), or None for a name we do not know."""
    return BUFFER_CHANNELS.get(name.removesuffix("_var"))


@dataclass
class Frame:
    """One rendered frame at one sample count.

    ``reference`` is the high-spp color (H×W×3) when the dataset has it; ``spp`` the sample count of
    the noisy buffers; ``index`` the frame's position in its sequence.
    """

    buffers: dict[str, np.ndarray]
    spp: int = 0
    scene: str = ""
    index: int = 0
    reference: np.ndarray | None = None
    samples: Mapping[str, np.ndarray] | None = None
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if "color" not in self.buffers:
            raise ValueError("a Frame needs at least a 'color' buffer")
        height, width = self.buffers["color"].shape[:2]
        for name, array in self.buffers.items():
            if array.ndim != 3 or array.shape[:2] != (height, width):
                raise ValueError(f"buffer {name!r} has shape {array.shape}, expected {height}×{width}×C like 'color'")
            channels = expected_channels(name)
            if channels is not None and array.shape[2] != channels:
                raise ValueError(f"buffer {name!r} has {array.shape[2]} channels, expected {channels}")

    @property
    def height(self) -> int:
        return self.buffers["color"].shape[0]

    @property
    def width(self) -> int:
        return self.buffers["color"].shape[1]

    @property
    def color(self) -> np.ndarray:
        return self.buffers["color"]

    def has(self, name: str) -> bool:
        """True when the frame carries buffer ``name`` (``"samples"`` asks for per-sample data)."""
        if name == "samples":
            return self.samples is not None
        return name in self.buffers


@dataclass
class Sequence:
    """Consecutive frames of one scene at one sample count, in camera-time order."""

    scene: str
    spp: int
    frames: list[Frame]
    meta: dict = field(default_factory=dict)

    def __iter__(self) -> Iterator[Frame]:
        return iter(self.frames)

    def __len__(self) -> int:
        return len(self.frames)

    def __getitem__(self, index: int) -> Frame:
        return self.frames[index]
