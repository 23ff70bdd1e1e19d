"""diathermy: an electrosurgery simulator (electro-thermo-mechanical FEM with a level-set cut)."""

from diathermy.version import __version__

__all__ = ["__version__"]
