"""Find and load the Embree 4 shared library, and declare the few functions embree_rt calls.

The library normally comes from inside the ``embreex`` wheel (``embreex.libs/libembree4-*.so.4``);
``EMBREE_RT_LIBRARY=/path/to/libembree4.so`` selects another Embree 4 build.
"""

from __future__ import annotations

import ctypes
import glob
import importlib.util
import os
from pathlib import Path

LIBRARY_ENV = "EMBREE_RT_LIBRARY"

# Enumerations and formats from Embree 4's public headers (rtcore_*.h).
GEOMETRY_TYPE_TRIANGLE = 0
GEOMETRY_TYPE_ROUND_LINEAR_CURVE = 16
GEOMETRY_TYPE_SPHERE_POINT = 50
GEOMETRY_TYPE_USER = 120
GEOMETRY_TYPE_INSTANCE = 121
GEOMETRY_TYPE_INSTANCE_ARRAY = 122
BUFFER_TYPE_INDEX = 0
BUFFER_TYPE_VERTEX = 1
BUFFER_TYPE_TRANSFORM = 23
FORMAT_UINT = 0x5001
FORMAT_UINT3 = 0x5003
FORMAT_FLOAT3 = 0x9003
FORMAT_FLOAT4 = 0x9004
FORMAT_FLOAT3X4_ROW_MAJOR = 0x9134
FORMAT_FLOAT4X4_COLUMN_MAJOR = 0x9244
DEVICE_PROPERTY_NATIVE_RAY4_SUPPORTED = 32
DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED = 33
DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED = 34
INVALID_ID = 0xFFFFFFFF
# RTCBuildQuality (rtcore_common.h) by name, and RTCSceneFlags (rtcore_scene.h).
BUILD_QUALITY = {"low": 0, "medium": 1, "high": 2}
BUILD_QUALITY_REFIT = 3  # a geometry's BVH refitted, not rebuilt, when it is committed again
SCENE_FLAG_DYNAMIC = 1 << 0
SCENE_FLAG_COMPACT = 1 << 1
SCENE_FLAG_ROBUST = 1 << 2
SCENE_FLAG_FILTER_FUNCTION_IN_ARGUMENTS = 1 << 3

ERROR_NAMES = {
    0: "RTC_ERROR_NONE",
    1: "RTC_ERROR_UNKNOWN",
    2: "RTC_ERROR_INVALID_ARGUMENT",
    3: "RTC_ERROR_INVALID_OPERATION",
    4: "RTC_ERROR_OUT_OF_MEMORY",
    5: "RTC_ERROR_UNSUPPORTED_CPU",
    6: "RTC_ERROR_CANCELLED",
}

ErrorCallback = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_int, ctypes.c_char_p)


class EmbreeError(RuntimeError):
    """An error reported by the Embree library itself, carrying Embree's message."""


def find_library() -> Path:
    """Path of the Embree 4 library to load: ``$EMBREE_RT_LIBRARY`` or the one inside embreex."""
    override = os.environ.get(LIBRARY_ENV)
    if override:
        path = Path(override)
        if not path.is_file():
            raise EmbreeError(f"{LIBRARY_ENV}={override}: no such file")
        return path
    spec = importlib.util.find_spec("embreex")
    if spec is None or not spec.submodule_search_locations:
        raise EmbreeError(
            "the embreex package is not installed, so no Embree 4 library was found; "
            f"install embreex or set {LIBRARY_ENV} to a libembree4 shared library"
        )
    package_dir = Path(next(iter(spec.submodule_search_locations)))
    candidates = sorted(glob.glob(str(package_dir.parent / "embreex.libs" / "libembree4*")))
    candidates += sorted(glob.glob(str(package_dir / "libembree4*")))
    if not candidates:
        raise EmbreeError(
            f"no libembree4 library inside the embreex installation at {package_dir}; "
            f"set {LIBRARY_ENV} to a libembree4 shared library"
        )
    return Path(candidates[0])


def _declare(lib: ctypes.CDLL) -> None:
    p, u, i, z = ctypes.c_void_p, ctypes.c_uint, ctypes.c_int, ctypes.c_size_t
    signatures = {
        "rtcNewDevice": (p, [ctypes.c_char_p]),
        "rtcReleaseDevice": (None, [p]),
        "rtcGetDeviceProperty": (ctypes.c_ssize_t, [p, i]),
        "rtcGetDeviceError": (i, [p]),
        "rtcSetDeviceErrorFunction": (None, [p, ErrorCallback, p]),
        "rtcNewScene": (p, [p]),
        "rtcReleaseScene": (None, [p]),
        "rtcCommitScene": (None, [p]),
        "rtcGetSceneBounds": (None, [p, p]),
        "rtcSetSceneBuildQuality": (None, [p, i]),
        "rtcSetSceneFlags": (None, [p, i]),
        "rtcSetGeometryBuildQuality": (None, [p, i]),
        "rtcAttachGeometry": (u, [p, p]),
        "rtcNewGeometry": (p, [p, i]),
        "rtcReleaseGeometry": (None, [p]),
        "rtcCommitGeometry": (None, [p]),
        "rtcSetNewGeometryBuffer": (p, [p, i, u, i, z, z]),
        "rtcSetGeometryInstancedScene": (None, [p, p]),
        "rtcSetGeometryInstancedScenes": (None, [p, p, z]),
        "rtcSetSharedGeometryBuffer": (None, [p, i, u, i, p, z, z, z]),
        "rtcSetGeometryTransform": (None, [p, u, i, p]),
        "rtcSetGeometryUserPrimitiveCount": (None, [p, u]),
        "rtcSetGeometryUserData": (None, [p, p]),
        "rtcSetGeometryBoundsFunction": (None, [p, p, p]),
        "rtcSetGeometryIntersectFunction": (None, [p, p]),
        "rtcSetGeometryOccludedFunction": (None, [p, p]),
        "rtcSetGeometryIntersectFilterFunction": (None, [p, p]),
        "rtcSetGeometryOccludedFilterFunction": (None, [p, p]),
        "rtcGetGeometry": (p, [p, u]),
        "rtcUpdateGeometryBuffer": (None, [p, i, u]),
    }
    for name, (restype, argtypes) in signatures.items():
        function = getattr(lib, name)
        function.restype = restype
        function.argtypes = argtypes


_library: ctypes.CDLL | None = None


def load_library() -> ctypes.CDLL:
    """The loaded Embree library with its functions declared (loaded once per process)."""
    global _library
    if _library is None:
        path = find_library()
        try:
            lib = ctypes.CDLL(str(path), mode=ctypes.RTLD_GLOBAL)
        except OSError as error:
            raise EmbreeError(f"cannot load the Embree library {path}: {error}") from None
        try:
            _declare(lib)
        except AttributeError as error:
            raise EmbreeError(f"{path} is not an Embree 4 library: {error}") from None
        _library = lib
    return _library


def function_address(name: str) -> int:
    """Address of an exported Embree function, for the compiled query kernels."""
    return ctypes.cast(getattr(load_library(), name), ctypes.c_void_p).value
