"""Imported by the fork server of forked.py, and only there: every service kernel loaded from
numba's cache (`omninav warm` put them there), so the services forked from it share them instead
of each loading its own copy (about 40 MB a process)."""
from .kernels import warm_all

try:
    warm_all()
except Exception:    # noqa: BLE001 — a kernel that will not load here is loaded by its service, which says why
    pass
