"""python/examples/ray_sweep.py on a local Ray: the sweep's periods against 2π√(l/g)."""
import importlib.util
import pathlib

import pytest

ray = pytest.importorskip("ray", reason="the Ray example needs `pip install ray` (CI installs it)")

EXAMPLE = pathlib.Path(__file__).resolve().parents[1] / "examples/ray_sweep.py"


def test_the_ray_sweep_finds_the_pendulums_periods():
    spec = importlib.util.spec_from_file_location("ray_sweep", EXAMPLE)
    sweep = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(sweep)
    ray.init(num_cpus=2, include_dashboard=False)
    try:
        lengths = [0.5, 1.0, 2.0, 4.0]
        found = sweep.sweep(lengths, chunks=2, duration=4.5)
    finally:
        ray.shutdown()
    for length, period in zip(lengths, found):
        assert period == pytest.approx(sweep.expected(length), rel=2e-4), length
    assert found[3] / found[1] == pytest.approx(2.0, rel=1e-4)
