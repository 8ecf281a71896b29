"""trep.visual: the viewer a trep script ends with, drawn with matplotlib (its animation
saved to a file here; a window otherwise)."""
import math
import sys

import numpy as np
import pytest

from tree_mech import trep
from tree_mech.trep import visual


def pendulum():
    s = trep.System()
    s.import_frames([trep.rx("theta", name="pivot"), [trep.tz(-1.0, mass=2.0, name="bob")]])
    trep.potentials.Gravity(s)
    return s


def test_an_item_puts_the_system_on_its_trajectory_and_draws_its_frames():
    s = pendulum()
    t = [0.0, 0.1, 0.2]
    item = visual.VisualItem3D(s, t, [[0.0], [0.4], [0.2]])
    assert item.getTimeRange()[:2] == (0.0, 0.2)
    item.setTime(0.05)  # halfway between the first two samples
    assert s.q[0] == pytest.approx(0.2, abs=1e-15) and s.t == 0.05
    item.setTime(7.0)  # clamped to the end
    assert s.q[0] == pytest.approx(0.2, abs=1e-15)
    lines, masses = item.skeleton()
    # The bob hangs 1 below the pivot, turned by θ about x: (0, sin θ, −cos θ).
    bob = np.array([0.0, math.sin(0.2), -math.cos(0.2)])
    assert any(np.allclose(b, bob, atol=1e-14) for _, b in lines)
    assert len(masses) == 1 and np.allclose(masses[0][0], bob) and masses[0][1] == 2.0
    # Seen from the front as the Puppet's view is: world −y along the picture's x.
    item.setOrientation(forward=[0, -1, 0], up=[0, 0, 1])
    assert np.allclose(item.skeleton()[1][0][0], [-bob[1], bob[0], bob[2]], atol=1e-14)
    flat = visual.VisualItem2D(s, t, [[0.0], [0.4], [0.2]], plane="YZ")
    flat.setTime(0.2)
    assert np.allclose(flat.skeleton()[1][0][0], bob[1:], atol=1e-14)
    with pytest.raises(ValueError, match="plane 'XX'"):
        visual.VisualItem2D(s, plane="XX")
    with pytest.raises(ValueError, match="forward and up must be nonzero and not parallel"):
        item.setOrientation(forward=[0, 0, 2], up=[0, 0, 1])
    with pytest.raises(ValueError, match="one configuration per time"):
        visual.VisualItem3D(s, [0.0, 1.0], [[0.0]])


def test_a_script_ending_with_the_viewer_writes_its_animation(tmp_path):
    pytest.importorskip("matplotlib")
    from PIL import Image
    s = pendulum()
    s.q = [1.0]
    mvi = trep.MidpointVI(s)
    mvi.initialize_from_configs(0.0, s.q, 0.02, s.q)
    t, q = [mvi.t1], [mvi.q1]
    while mvi.t1 < 0.4:
        mvi.step(mvi.t2 + 0.02)
        t.append(mvi.t1)
        q.append(mvi.q1)
    out = tmp_path / "swing.gif"
    assert visual.visualize_3d([visual.VisualItem3D(s, t, q)], save=str(out)) == 0
    with Image.open(out) as gif:
        assert gif.n_frames == round((t[-1] - t[0]) * visual.FPS) + 1
    flat = tmp_path / "flat.gif"
    visual.visualize_2d([visual.VisualItem2D(s, t, q, plane="YZ")], save=str(flat))
    assert flat.stat().st_size > 0


def test_the_puppets_view_draws_trep_puppet(tmp_path):
    pytest.importorskip("matplotlib")
    p = trep.puppets.Puppet(string_constraints=True)
    p.get_config("torso_tz").q = 1.1
    q = np.array([p.q, p.q])
    item = trep.puppets.PuppetVisual(p, [0.0, 0.04], q)
    assert np.allclose(item.orientation()[:3, :3] @ [0, -1, 0], [1, 0, 0])
    out = tmp_path / "puppet.gif"
    trep.visual.visualize_3d([item], save=str(out))
    assert out.stat().st_size > 0


def test_without_matplotlib_the_viewer_says_what_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    monkeypatch.setitem(sys.modules, "matplotlib.pyplot", None)
    s = pendulum()
    with pytest.raises(ImportError, match="pip install matplotlib"):
        visual.visualize_3d([visual.VisualItem3D(s, [0.0], [[0.0]])])


def test_without_a_window_the_viewer_says_to_save(monkeypatch):
    matplotlib = pytest.importorskip("matplotlib")
    monkeypatch.setattr(matplotlib, "get_backend", lambda: "agg")
    s = pendulum()
    with pytest.warns(RuntimeWarning, match="pass save='run.gif'"):
        assert visual.visualize_3d([visual.VisualItem3D(s, [0.0], [[0.0]])]) == 0


def test_an_stl_drawing_is_kept_and_a_missing_file_refused(tmp_path):
    mesh = tmp_path / "torso.stl"
    mesh.write_text("solid torso\nendsolid torso\n")
    s = pendulum()
    item = visual.VisualItem3D(s, [0.0], [[0.0]])
    item.attachDrawing("bob", visual.stlmodel(str(mesh)).draw)
    assert len(item.drawings) == 1 and item.drawings[0][0].name == "bob"
    assert item.drawings[0][1]() is None
    with pytest.raises(FileNotFoundError, match="no STL file"):
        visual.stlmodel(str(tmp_path / "missing.stl"))


def test_plot_spline_draws_the_spline_and_its_derivatives():
    pytest.importorskip("matplotlib")
    import warnings
    from tree_mech.trep.visual.splineplotter import plot_spline
    spline = trep.Spline([[0.0, 0.0], [1.0, 2.0], [2.0, 1.0]])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Agg cannot show
        fig = plot_spline(spline, points=50)
    axes = fig.get_axes()
    assert len(axes) == 3
    x, y = axes[0].lines[0].get_data()
    assert len(x) == 50 and y[-1] == pytest.approx(spline.y(2.0))
