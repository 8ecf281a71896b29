"""README.md's Python example runs as written, from the repository's root, and its results
have the shapes and the physics its comments say."""
import os
import pathlib
import re

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[2]


def readme_python_blocks():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    return re.findall(r"```python\n(.*?)```", text, flags=re.S)


def test_the_readme_python_example_runs_and_means_what_it_says():
    blocks = readme_python_blocks()
    assert len(blocks) == 1, "README.md has one Python example"
    here = os.getcwd()
    os.chdir(ROOT)
    try:
        scope = {}
        exec(compile(blocks[0], "README.md", "exec"), scope)
    finally:
        os.chdir(here)
    # The pole, tipped 0.3 rad from upright, falls further from upright.
    qdd = np.asarray(scope["qdd"])
    assert qdd.shape == (2,) and qdd[1] > 0.0
    lin = scope["lin"]
    assert lin["qdd_dq"].shape == (2, 2) and lin["vi"]["q2_dq1"].shape == (2, 2)
    traj = scope["traj"]
    assert traj.q.shape == (201, 2) and np.all(np.isfinite(traj.energy))
    # The cart held within 0.1 m of x = 0 by its PD while the pole, let go 0.3 rad from
    # upright, falls through hanging (θ = π) within the 1 s.
    s = scope["s"]
    assert abs(s.t - 1.0) < 1e-12 and abs(s.q[0]) < 0.1 and s.q[1] > np.pi
    batch = scope["batch"]
    assert batch.q.shape[0] == 64 and all(e is None for e in batch.errors)
    assert scope["plan"]["converged"]
