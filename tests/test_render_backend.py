"""MuJoCo's offscreen backend on a headless machine (s3rl_torchrl/_render_backend.py)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from s3rl_torchrl import _render_backend as backend


def test_selection_happens_only_without_display_and_without_mujoco_gl():
    assert backend.needs_selection({}, "Linux")
    assert not backend.needs_selection({"DISPLAY": ":0"}, "Linux")
    assert not backend.needs_selection({"WAYLAND_DISPLAY": "wayland-0"}, "Linux")
    assert not backend.needs_selection({"MUJOCO_GL": "osmesa"}, "Linux")  # the user's choice
    assert not backend.needs_selection({}, "Darwin")  # MuJoCo's CGL needs nothing


def test_egl_first_then_osmesa_then_none():
    assert backend.choose_backend(lambda lib: True) == "egl"
    assert backend.choose_backend(lambda lib: lib.startswith("libOSMesa")) == "osmesa"
    assert backend.choose_backend(lambda lib: False) is None


def test_no_backend_is_one_line_naming_the_debian_packages(monkeypatch):
    monkeypatch.delenv("MUJOCO_GL", raising=False)
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(backend.platform, "system", lambda: "Linux")
    with pytest.raises(backend.RenderBackendError) as err:
        backend.require_render_backend()
    message = str(err.value)
    assert "\n" not in message and "libegl-mesa0" in message and "libosmesa6" in message
    monkeypatch.setenv("MUJOCO_GL", "osmesa")
    monkeypatch.setattr(backend, "library_loads", lambda lib: False)
    with pytest.raises(backend.RenderBackendError, match="apt-get install libosmesa6"):
        backend.require_render_backend()


@pytest.mark.slow  # a fresh interpreter importing the package: ~5-13 s
def test_a_fresh_process_without_display_renders_with_what_import_chose():
    # This machine's image: Mesa's EGL (libegl-mesa0), no OSMesa (docs/video.md).
    env = {k: v for k, v in os.environ.items()
           if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "DISPLAY", "WAYLAND_DISPLAY")}
    code = (
        "import os, s3rl_torchrl, mujoco\n"
        "from s3rl_torchrl._render_backend import require_render_backend\n"
        "require_render_backend()\n"
        "model = mujoco.MjModel.from_xml_string('<mujoco><worldbody><light pos=\"0 0 1\"/>"
        "<geom type=\"sphere\" size=\"0.1\"/></worldbody></mujoco>')\n"
        "renderer = mujoco.Renderer(model, 16, 16)\n"
        "renderer.update_scene(mujoco.MjData(model))\n"
        "print(os.environ['MUJOCO_GL'], renderer.render().shape)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split("\n")[-2] == "egl (16, 16, 3)"
