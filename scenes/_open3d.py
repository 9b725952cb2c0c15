"""Import open3d after loading the libusb it links against.

open3d's shared library needs ``libusb-1.0.so.0``, which a fresh Linux machine often lacks. The
``libusb-package`` wheel carries that library; loading it globally first lets ``import open3d``
succeed with no system package installed.
"""

from __future__ import annotations

import ctypes
import functools
from types import ModuleType


@functools.cache
def open3d() -> ModuleType:
    """The ``open3d`` module, imported once, with libusb preloaded when it is available."""
    try:
        import libusb_package

        path = libusb_package.get_library_path()
        if path is not None:
            ctypes.CDLL(str(path), mode=ctypes.RTLD_GLOBAL)
    except (ImportError, OSError):  # pragma: no cover - a system libusb may still be there
        pass
    import open3d as o3d

    return o3d
