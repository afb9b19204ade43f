"""The shared core: skeleton, geometry, kinematics, the manifest schema and file I/O.

Imports neither torch nor FastAPI; ``service`` and ``trainer`` both import it, it imports
neither of them.
"""
