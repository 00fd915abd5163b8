"""The benchmark case families, one module each. Importing this package registers them; the
order of the imports is the order of the tables in BENCHMARKS.md and of the runs."""

from . import static  # noqa: F401  (cantilevers, standard formulation)
from . import hammerbot  # noqa: F401  (the paper's robot, standard and mixed)
from . import mixed  # noqa: F401  (cantilevers, mixed formulation)
from . import materials  # noqa: F401  (Yeoh against Neo-Hookean, side by side)
from . import cables  # noqa: F401
from . import tendons  # noqa: F401  (tendons against spring chains, side by side)
from . import dynamics  # noqa: F401
from . import realtime  # noqa: F401  (the fast step mode against the clock)
from . import adjoint  # noqa: F401
from . import trajectory  # noqa: F401  (the adjoint through time)
from . import trajectory_contact  # noqa: F401  (the adjoint through time and contact)
from . import contact  # noqa: F401  (the cantilever on a floor, with and without it)
from . import contact_finger  # noqa: F401  (a finger on a ball; self-contact on and off)
from . import contact_peer  # noqa: F401  (the contact pass against ipctk)
from . import sweep  # noqa: F401  (sweeps on a Dask LocalCluster)
from . import peers  # noqa: F401  (scikit-fem, and the comparison section)
