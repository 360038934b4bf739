"""Colour and depth of a MuJoCo camera in one render pass, headless.

MuJoCo's stock ``Renderer`` renders the scene once for colour and again for depth, each time
with the light's shadow map; on a CPU rasteriser (Mesa llvmpipe) that is most of the cost. Here
one ``mjr_render`` fills both buffers and one ``mjr_readPixels`` reads both back, with shadows
and reflections off (the scene's light does not cast shadows anyway).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import mujoco
import numpy as np
import numpy.typing as npt
from mujoco.rendering.classic.gl_context import GLContext

from onebox.errors import SceneError
from onebox.world.scene import MAX_RANGE_M, CameraSpec
from onebox.world.spec import MIN_RANGE_M


@dataclass
class Capture:
    """One camera's pictures: rgb8 rows top first, depth in metres (NaN = no reading)."""

    rgb: npt.NDArray[np.uint8]
    depth_m: npt.NDArray[np.float32]


class SceneRenderer:
    """Renders the model's cameras; one GL context and one scene for all of them."""

    def __init__(self, model: mujoco.MjModel, cameras: list[CameraSpec]) -> None:
        self._model = model
        self._cameras = {c.name: c for c in cameras}
        self._ids = {}
        for c in cameras:
            cam_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, c.name)
            if cam_id < 0:
                raise SceneError(f"the scene has no camera named {c.name!r}")
            self._ids[c.name] = cam_id
        width = max(c.width for c in cameras)
        height = max(c.height for c in cameras)
        try:
            self._gl = GLContext(width, height)
            self._gl.make_current()
        except Exception as e:  # each GL backend raises its own error type
            raise SceneError(
                f"cannot open a headless OpenGL context with MUJOCO_GL={os.environ['MUJOCO_GL']}: "
                f"{e}. Install Mesa's EGL (Debian: libegl1 libgl1-mesa-dri) or try MUJOCO_GL=osmesa"
            ) from e
        self._context = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_100)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._context)
        # Read depth as 0 at the far plane (reversed Z), the mapping _metres undoes.
        self._context.readDepthMap = mujoco.mjtDepthMap.mjDEPTH_ZEROFAR
        self._scene = mujoco.MjvScene(model, maxgeom=1000)
        self._scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
        self._scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = False
        self._scene.flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = False
        self._option = mujoco.MjvOption()
        self._camera = mujoco.MjvCamera()
        self._camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
        # glFrustum's depth mapping in MuJoCo's reversed-Z mode, in float32 as the GPU has it.
        extent = model.stat.extent
        near = np.float32(model.vis.map.znear * extent)
        far = np.float32(model.vis.map.zfar * extent)
        c_coef = -(far + near) / (far - near)
        d_coef = -(np.float32(2) * far * near) / (far - near)
        self._c = float(np.float32(-0.5) * c_coef - np.float32(0.5))
        self._d = float(np.float32(-0.5) * d_coef)
        self._buffers = {
            c.name: (
                np.empty((c.height, c.width, 3), np.uint8),
                np.empty((c.height, c.width), np.float32),
            )
            for c in cameras
        }

    def render(self, data: mujoco.MjData, camera: str) -> Capture:
        """Colour and depth of ``camera`` as the world is in ``data`` (new arrays each call)."""
        self.draw(data, camera)
        return self.read(camera)

    def draw(self, data: mujoco.MjData, camera: str) -> None:
        """Queue the drawing of ``camera``'s view (the rasteriser may finish it in ``read``)."""
        spec = self._cameras[camera]
        self._camera.fixedcamid = self._ids[camera]
        mujoco.mjv_updateScene(
            self._model,
            data,
            self._option,
            None,
            self._camera,
            mujoco.mjtCatBit.mjCAT_ALL,
            self._scene,
        )
        mujoco.mjr_render(mujoco.MjrRect(0, 0, spec.width, spec.height), self._scene, self._context)

    def read(self, camera: str) -> Capture:
        """Read back what ``draw`` drew: both buffers in one call, flipped to top row first."""
        spec = self._cameras[camera]
        rgb_gl, depth_gl = self._buffers[camera]
        rect = mujoco.MjrRect(0, 0, spec.width, spec.height)
        mujoco.mjr_readPixels(rgb_gl, depth_gl, rect, self._context)
        # OpenGL's rows run bottom to top.
        return Capture(rgb=rgb_gl[::-1].copy(), depth_m=self._metres(depth_gl[::-1]))

    def _metres(self, depth_gl: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
        """Undo the projection; NaN outside the camera's range, as a real depth camera reads."""
        depth = np.add(depth_gl, np.float32(self._c), dtype=np.float32)
        np.divide(np.float32(self._d), depth, out=depth)
        depth[(depth < MIN_RANGE_M) | (depth > MAX_RANGE_M)] = np.nan
        return depth

    def close(self) -> None:
        self._context.free()
        self._gl.free()

    def __enter__(self) -> SceneRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
