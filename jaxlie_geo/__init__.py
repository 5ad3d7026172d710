"""jaxlie_geo: Lie groups for rigid-body motion in JAX.

A drop-in superset of jaxlie 1.5 (``import jaxlie_geo as jaxlie``) with exact numerics,
closed-form vector kernels, ``hat``/``vee``, geodesics and batch indexing.
"""

from importlib.metadata import PackageNotFoundError as _PackageNotFoundError
from importlib.metadata import version as _version

from . import bundle as bundle
from . import hints as hints
from . import interop as interop
from . import jacobians as jacobians
from . import least_squares as least_squares
from . import manifold as manifold
from . import motion as motion
from . import pose_graph as pose_graph
from . import splines as splines
from . import uncertainty as uncertainty
from . import utils as utils
from ._base import MatrixLieGroup as MatrixLieGroup
from ._base import SEBase as SEBase
from ._base import SOBase as SOBase
from ._batch import stack as stack
from ._geodesic import Geodesic as Geodesic
from ._geodesic import between as between
from ._geodesic import geodesic as geodesic
from ._se2 import SE2 as SE2
from ._se3 import SE3 as SE3
from ._se23 import SE23 as SE23
from ._sim3 import Sim3 as Sim3
from ._so2 import SO2 as SO2
from ._so3 import SO3 as SO3
from ._validity import check_valid as check_valid

try:
    __version__ = _version("jaxlie_geo")
except _PackageNotFoundError:  # imported from a source tree that was never installed
    __version__ = "0.0.0+unknown"

__all__ = [
    "MatrixLieGroup",
    "SOBase",
    "SEBase",
    "SO2",
    "SE2",
    "SO3",
    "SE3",
    "Sim3",
    "SE23",
    "Geodesic",
    "geodesic",
    "between",
    "stack",
    "check_valid",
    "bundle",
    "hints",
    "interop",
    "jacobians",
    "least_squares",
    "manifold",
    "motion",
    "pose_graph",
    "splines",
    "uncertainty",
    "utils",
]
