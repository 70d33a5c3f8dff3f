"""Gymnasium is an optional dependency: import it here, with an install hint when it is missing."""

from __future__ import annotations

INSTALL_HINT = (
    'the Gymnasium environments need gymnasium: pip install "safelane[gym]" (or: pip install "gymnasium>=1.0")'
)


def require_gymnasium():
    """The ``gymnasium`` module, or an ``ImportError`` saying how to install it."""
    try:
        import gymnasium
    except ImportError as exc:  # pragma: no cover - exercised only without the extra
        raise ImportError(INSTALL_HINT) from exc
    return gymnasium
