"""Model solutions for the geometry-and-interpolation course (numpy/scipy only).

The public functions of the submodules are re-exported here:

- :mod:`reference.geometry`: :func:`orient2d`, :func:`convex_hull`
- :mod:`reference.interpolation`: :func:`equispaced_nodes`, :func:`chebyshev_nodes`,
  :func:`equispaced_weights`, :func:`chebyshev_weights`, :func:`barycentric_weights`,
  :func:`barycentric_interpolate`, :func:`lebesgue_constant`
- :mod:`reference.bezier`: :func:`bernstein`, :func:`bezier`, :func:`de_casteljau`,
  :func:`split`
- :mod:`reference.splines`: :class:`CubicSpline`, :class:`ParametricSpline`,
  :func:`parametric_spline`
- :mod:`reference.delaunay`: :func:`incircle`, :func:`delaunay`, :func:`is_delaunay`
- :mod:`reference.plotting`: :func:`plot_points_and_hull`, :func:`plot_de_casteljau`,
  :func:`plot_interpolant`, :func:`plot_spline`, :func:`plot_car`, :func:`tplot`
- :mod:`reference.data`: :func:`car`, :data:`CAR_STROKE_NAMES`, :func:`save_car`,
  :func:`load_strokes`

Two functions share the name of their module: after ``import reference``,
``reference.bezier`` and ``reference.delaunay`` are the *functions*.  Reach the
modules with ``from reference.bezier import de_casteljau`` or
``importlib.import_module("reference.delaunay")``.
"""

from reference import bezier as _bezier_module
from reference import data, geometry, interpolation, plotting, splines
from reference import delaunay as _delaunay_module
from reference.bezier import *  # noqa: F403
from reference.data import *  # noqa: F403
from reference.delaunay import *  # noqa: F403
from reference.geometry import *  # noqa: F403
from reference.interpolation import *  # noqa: F403
from reference.plotting import *  # noqa: F403
from reference.splines import *  # noqa: F403

__all__ = [
    *geometry.__all__,
    *interpolation.__all__,
    *_bezier_module.__all__,
    *splines.__all__,
    *_delaunay_module.__all__,
    *plotting.__all__,
    *data.__all__,
]
