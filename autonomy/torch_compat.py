"""The two places where the project leans on torch APIs that are moving: TorchScript and the PT2 archive.

* TorchScript is deprecated in torch 2.13: every ``torch.jit.script`` / ``save`` / ``load`` call emits a
  ``DeprecationWarning`` ("`torch.jit.script` is deprecated. Please switch to ..."). TorchScript is still the
  format an on-board runtime can load with nothing but libtorch, so the project keeps using it, and silences
  exactly that warning around exactly those calls with :func:`torchscript_calls` (one helper, used by the
  exporter and the runtime alike). Any other warning still shows.
* ``torch.export`` is the way forward. A policy needs two entry points (``act`` and ``select_goal``) and one
  file; ``torch.export.save`` writes a PT2 archive with a single program named ``"model"``, but the archive
  format itself holds several named programs (``torch.export.save`` / ``load`` are thin wrappers over
  ``package_pt2`` / ``load_pt2``). Those two live in a private module, so :func:`pt2_archive` is the only place
  that imports it and turns its absence into one clear error.
"""
from __future__ import annotations

import contextlib
import warnings
from collections.abc import Iterator
from types import ModuleType

import torch

TORCHSCRIPT_DEPRECATION = r"`torch\.jit\.\w+` is deprecated"


@contextlib.contextmanager
def torchscript_calls() -> Iterator[None]:
    """Run ``torch.jit`` calls without torch 2.13's TorchScript deprecation warning (and only that warning)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=TORCHSCRIPT_DEPRECATION, category=DeprecationWarning)
        yield


def pt2_archive() -> ModuleType:
    """torch's PT2 archive module (``package_pt2`` / ``load_pt2``: several named programs in one file)."""
    try:
        from torch.export.pt2_archive import _package
    except ImportError as exc:
        raise ImportError(f"torch {torch.__version__} has no PT2 archive support (torch.export.pt2_archive); "
                          "use the TorchScript format") from exc
    return _package
