"""trep's ``trep.system`` module, for scripts that reach through it: the ``System`` class and
the trajectory files (``save_trajectory``, ``load_trajectory``), as the package has them."""
from ._core import System
from ._trajectory import load_trajectory, save_trajectory

__all__ = ["System", "load_trajectory", "save_trajectory"]
