"""The shared core: skeleton, geometry, kinematics, the manifest schema and file I/O.

Imports neither torch nor FastAPI; ``service`` and ``trainer`` both import it, it imports
neither of them.
"""


class CacheDirError(RuntimeError):
    """No folder to keep the compiled kernels in (``pose-service`` says so in one line).

    Raised while :mod:`core.jit` is imported (it chooses the folder then), so it is defined
    here, where a caller can import it before that import runs."""
