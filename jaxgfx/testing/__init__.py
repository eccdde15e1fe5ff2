"""jaxgfx.testing: public tools to test samplers and BSDFs (chi², finite differences, furnace).

See ``docs/render_bsdf.md``.
"""

from jaxgfx.testing._chi2 import chi2_test as chi2_test
from jaxgfx.testing._finite_difference import GradStats as GradStats
from jaxgfx.testing._finite_difference import ad_fd_per_key as ad_fd_per_key
from jaxgfx.testing._finite_difference import check_grads_fd as check_grads_fd
from jaxgfx.testing._finite_difference import check_grads_jit as check_grads_jit
from jaxgfx.testing._finite_difference import grad_stats as grad_stats
from jaxgfx.testing._furnace import furnace as furnace
from jaxgfx.testing._hlo import unordered_lapack_calls as unordered_lapack_calls

__all__ = [
    "chi2_test",
    "check_grads_fd",
    "check_grads_jit",
    "ad_fd_per_key",
    "grad_stats",
    "GradStats",
    "furnace",
    "unordered_lapack_calls",
]
