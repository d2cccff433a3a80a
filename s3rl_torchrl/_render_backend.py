"""MuJoCo's offscreen OpenGL backend on a headless machine, chosen before MuJoCo is imported.

MuJoCo reads ``MUJOCO_GL`` once, when ``mujoco`` is first imported; unset, it uses GLFW, which
needs a display: on a headless machine a video then ends in ``mujoco.FatalError: an OpenGL
platform library has not been loaded into this process``. :func:`select_mujoco_gl` runs first
on ``import s3rl_torchrl`` and, only when no display is set (``DISPLAY``, ``WAYLAND_DISPLAY``)
and ``MUJOCO_GL`` is unset, sets it to the first backend whose library loads: EGL
(``libEGL.so.1``; Mesa's runs on the CPU), then OSMesa (``libOSMesa.so``). Loading a library
is a ``dlopen`` (well under a millisecond); whether the backend really renders (an EGL display
initialises: 35 ms warm, ~0.5 s cold, Mesa's driver loads; once per process) is checked only
when something is about to render (:func:`require_render_backend`), so that runs which never
render pay nothing. A value set by the user, and every machine with a display, is left alone. Child processes
(vector envs, ``ParallelEnv`` workers) inherit the choice through the environment.
"""

from __future__ import annotations

import ctypes
import os
import platform
import sys
from collections.abc import Callable, Mapping
from functools import cache

#: Backends tried in order, with the library each loads and the Debian package that has it.
BACKENDS: dict[str, tuple[str, str]] = {
    "egl": ("libEGL.so.1", "libegl-mesa0"),
    "osmesa": ("libOSMesa.so.8", "libosmesa6"),
}

# EGL's device platform, as mujoco/egl uses it (EGL_EXT_platform_device, EGL 1.5 values).
_EGL_PLATFORM_DEVICE_EXT = 0x313F
_MAX_EGL_DEVICES = 8


class RenderBackendError(RuntimeError):
    """No OpenGL backend renders here; the message is one line naming what to install."""


def library_loads(name: str) -> bool:
    """Whether the shared library ``name`` can be loaded into this process."""
    try:
        ctypes.CDLL(name)
    except OSError:
        return False
    return True


def needs_selection(environ: Mapping[str, str], system: str) -> bool:
    """Whether the package picks ``MUJOCO_GL``: Linux, no display and ``MUJOCO_GL`` unset."""
    if system != "Linux" or environ.get("MUJOCO_GL"):
        return False
    return not (environ.get("DISPLAY") or environ.get("WAYLAND_DISPLAY"))


def choose_backend(loads: Callable[[str], bool]) -> str | None:
    """The first of :data:`BACKENDS` whose library ``loads``; ``None`` if none does."""
    for backend, (library, _) in BACKENDS.items():
        if loads(library):
            return backend
    return None


#: What :func:`select_mujoco_gl` did on import: the backend it set, or ``None``.
selected: str | None = None


def select_mujoco_gl(environ=os.environ, system: str | None = None) -> str | None:
    """Set ``MUJOCO_GL`` (and PyOpenGL's platform, which must agree) when the machine has no
    display and the user set none; return the backend set, or ``None``. A no-op once MuJoCo is
    imported (it has read the variable already)."""
    global selected
    if "mujoco" in sys.modules or not needs_selection(environ, system or platform.system()):
        return None
    backend = choose_backend(library_loads)
    if backend is not None:
        environ["MUJOCO_GL"] = backend
        environ.setdefault("PYOPENGL_PLATFORM", backend)
        selected = backend
    return backend


@cache
def egl_initialises() -> bool:
    """Whether an EGL display initialises on one of the machine's EGL devices, as MuJoCo's
    ``mujoco.egl`` creates it (``eglGetPlatformDisplayEXT`` on a device, ``eglInitialize``)."""
    try:
        egl = ctypes.CDLL(BACKENDS["egl"][0])
    except OSError:
        return False
    egl.eglGetProcAddress.restype = ctypes.c_void_p
    egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]
    query_address = egl.eglGetProcAddress(b"eglQueryDevicesEXT")
    display_address = egl.eglGetProcAddress(b"eglGetPlatformDisplayEXT")
    if not query_address or not display_address:
        return False
    query_devices = ctypes.CFUNCTYPE(
        ctypes.c_uint, ctypes.c_int, ctypes.POINTER(ctypes.c_void_p), ctypes.POINTER(ctypes.c_int)
    )(query_address)
    platform_display = ctypes.CFUNCTYPE(
        ctypes.c_void_p, ctypes.c_uint, ctypes.c_void_p, ctypes.c_void_p
    )(display_address)
    egl.eglInitialize.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
    egl.eglInitialize.restype = ctypes.c_uint
    devices = (ctypes.c_void_p * _MAX_EGL_DEVICES)()
    count = ctypes.c_int(0)
    if not query_devices(_MAX_EGL_DEVICES, devices, ctypes.byref(count)):
        return False
    for device in devices[: count.value]:
        display = platform_display(_EGL_PLATFORM_DEVICE_EXT, device, None)
        # Not terminated afterwards: a device's display is one per process, the one MuJoCo's
        # renderer gets too, and eglTerminate would end it under a renderer already using it
        # (initialising it again is a no-op).
        if display and egl.eglInitialize(display, None, None):
            return True
    return False


def require_render_backend() -> None:
    """Raise :class:`RenderBackendError` (one line) if MuJoCo cannot render offscreen here.

    Checks only what this module can tell: the backend in ``MUJOCO_GL`` (``egl``: a display
    initialises; ``osmesa``: its library loads), or, with no display and no backend, that none
    was found. A display (GLFW), or a ``MUJOCO_GL`` this module does not know, is trusted."""
    backend = os.environ.get("MUJOCO_GL", "").lower()
    if backend == "egl":
        if not egl_initialises():
            raise RenderBackendError(
                "MuJoCo cannot render: MUJOCO_GL=egl, but no EGL display initialises; install "
                f"Mesa's EGL (Debian/Ubuntu: apt-get install {BACKENDS['egl'][1]}) or use "
                f"MUJOCO_GL=osmesa (apt-get install {BACKENDS['osmesa'][1]})."
            )
    elif backend == "osmesa":
        if not library_loads(BACKENDS["osmesa"][0]):
            raise RenderBackendError(
                f"MuJoCo cannot render: MUJOCO_GL=osmesa, but {BACKENDS['osmesa'][0]} does not "
                f"load; install it (Debian/Ubuntu: apt-get install {BACKENDS['osmesa'][1]})."
            )
    elif not backend and needs_selection(os.environ, platform.system()):
        raise RenderBackendError(
            "MuJoCo cannot render: no display and no offscreen OpenGL backend loads; install "
            f"EGL (Debian/Ubuntu: apt-get install {BACKENDS['egl'][1]}) or OSMesa "
            f"(apt-get install {BACKENDS['osmesa'][1]})."
        )
