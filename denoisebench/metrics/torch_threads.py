"""``one_torch_thread()``: run a block of small torch operations on one intra-op thread.

The torch-based metrics (cvvdp, msssim, the Noisebase SSIMs) run many small convolutions on
images of 16–256 px. Spread over torch's intra-op threads on a busy 2-core machine, the threads
spend their time waiting for each other: measured here for cvvdp on 8 frames of 128², 2 threads
took 3.5 s CPU / 10 s wall per call, one thread 0.17 s CPU / 0.40 s wall; msssim at 256² took
2.1 s with 2 threads. The thread count is process-wide state: the context restores the previous
count on exit, and it is not meant for code that runs torch on other Python threads meanwhile.
"""

from __future__ import annotations

from contextlib import contextmanager

# Lazy imports: torch (1 s) is imported only when a torch metric sets its thread count.

__all__ = ["one_torch_thread"]


@contextmanager
def one_torch_thread():
    """Set ``torch.set_num_threads(1)`` for the block; restore the previous count afterwards."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)
