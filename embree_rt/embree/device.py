"""The process-wide Embree device, and Embree's errors turned into Python exceptions.

All BVHs share one device because Embree can only instance a scene into another scene of the
same device. The device is reference-counted by the BVHs that use it and released with the last.
"""

from __future__ import annotations

import threading

from embree_rt.embree import library
from embree_rt.embree.library import EmbreeError

# User geometry (the spheres) in a 4-wide BVH: Embree picks an 8-wide one wherever AVX runs, and
# on issue 10's sphere fields (2 threads, AVX2, 8-ray packets; benchmarks/traversal.py) the
# 4-wide tree traced camera rays 1.05-1.4x and shadow rays 1.1-1.2x faster, with half-size
# nodes to fetch. Only user geometry's tree is affected; triangles and instances keep Embree's
# defaults.
DEVICE_CONFIG = b"verbose=0,object_accel=bvh4.object"


class Device:
    """One Embree device; ``check()`` raises the first error Embree reported since the last call."""

    def __init__(self) -> None:
        self.lib = library.load_library()
        self._errors: list[str] = []
        # Keep the callback object alive as long as the device: Embree holds its raw pointer.
        self._callback = library.ErrorCallback(self._on_error)
        self.handle = self.lib.rtcNewDevice(DEVICE_CONFIG)
        if not self.handle:
            raise EmbreeError("rtcNewDevice failed: this CPU or library cannot run Embree")
        self.lib.rtcSetDeviceErrorFunction(self.handle, self._callback, None)
        self.users = 0

    def _on_error(self, _user: int, code: int, message: bytes | None) -> None:
        name = library.ERROR_NAMES.get(code, f"error {code}")
        text = message.decode(errors="replace") if message else ""
        self._errors.append(f"{name}: {text}" if text else name)

    def check(self, action: str) -> None:
        if self._errors:
            errors, self._errors = self._errors, []
            raise EmbreeError(f"Embree failed in {action}: {'; '.join(errors)}")

    def property(self, prop: int) -> int:
        return int(self.lib.rtcGetDeviceProperty(self.handle, prop))

    def release(self) -> None:
        if self.handle:
            self.lib.rtcReleaseDevice(self.handle)
            self.handle = None


_lock = threading.Lock()
_shared: Device | None = None


def acquire() -> Device:
    """The shared device, created on first use; pair every call with ``release``."""
    global _shared
    with _lock:
        if _shared is None or _shared.handle is None:
            _shared = Device()
        _shared.users += 1
        return _shared


def release(device: Device) -> None:
    global _shared
    with _lock:
        device.users -= 1
        if device.users == 0:
            device.release()
            if _shared is device:
                _shared = None
