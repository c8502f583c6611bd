import os
from pathlib import Path

# Keep Warp's kernel cache inside the checkout's ignored build dir unless told otherwise.
os.environ.setdefault("WARP_CACHE_PATH", str(Path(__file__).resolve().parents[1] / "build" /
                                              "warp-cache"))

import pytest  # noqa: E402
import warp as wp  # noqa: E402

from warpspec._runtime import init  # noqa: E402

init()

DEVICES = ["cpu"] + (["cuda:0"] if wp.is_cuda_available() else [])


@pytest.fixture(params=["cpu", "cuda:0"])
def device(request):
    """Each test taking ``device`` runs on the CPU, and on CUDA when Warp sees a GPU."""
    if request.param not in DEVICES:
        pytest.skip("no CUDA device")
    return wp.get_device(request.param)
