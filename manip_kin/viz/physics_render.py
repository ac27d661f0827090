"""Offscreen pictures of a recorded run with MuJoCo's renderer: PNGs and a GIF (``manip_kin plot --render``).

The recording's ``robot_description`` becomes the same MuJoCo model the physics plant uses
(:mod:`manip_kin.plant.mujoco_model`: the URDF's collision shapes, or the default capsules of a
robot YAML) and every picked joint state is drawn by MuJoCo's OpenGL renderer without a display:
through EGL (``MUJOCO_GL=egl``, the default :mod:`manip_kin.plant` sets before mujoco is imported; Debian packages ``libegl1``, ``libegl-mesa0``
and ``libgl1-mesa-dri``, which render on the CPU with llvmpipe where there is no GPU) or OSMesa
(``MUJOCO_GL=osmesa``, package ``libosmesa6``).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from manip_kin.errors import InvalidArgumentError, OperationError

#: Picture size [pixels].
WIDTH, HEIGHT = 640, 480


def _renderer(mj_model):
    import mujoco

    try:
        return mujoco.Renderer(mj_model, HEIGHT, WIDTH)
    except Exception as error:  # noqa: BLE001 - whatever the GL layer raises, the reason goes to the user
        raise OperationError(
            f"offscreen rendering is not available (MUJOCO_GL={os.environ['MUJOCO_GL']}): "
            f"{type(error).__name__}: {error}; install libegl1 libegl-mesa0 libgl1-mesa-dri (EGL) or libosmesa6 "
            "(MUJOCO_GL=osmesa)"
        ) from None


def _scene_spec(urdf_text: str, mesh_search_path: str, scene):
    """The arm of ``urdf_text`` and ``scene``'s obstacles with a floor and lights (visual only), compiled."""
    import mujoco

    from manip_kin.core.urdf import load_urdf_string
    from manip_kin.plant.mujoco_model import JointDynamics, SpecSource, add_obstacles, build_spec

    model = load_urdf_string(urdf_text, source="the recorded robot_description")
    source = SpecSource(model, urdf_text, None, mesh_search_path)
    spec = build_spec(source, JointDynamics(), 1e-3)
    if scene is not None:
        add_obstacles(spec, scene, source)
    spec.visual.headlight.ambient = [0.35, 0.35, 0.35]
    spec.visual.headlight.diffuse = [0.6, 0.6, 0.6]
    world = spec.worldbody
    world.add_geom(
        type=mujoco.mjtGeom.mjGEOM_PLANE, size=[2, 2, 0.01], rgba=[0.9, 0.9, 0.85, 1], contype=0, conaffinity=0
    )
    world.add_light(pos=[0.5, -1.0, 3.0], dir=[-0.2, 0.3, -1.0], diffuse=[0.8, 0.8, 0.8])
    world.add_light(pos=[-1.0, 1.0, 2.0], dir=[0.4, -0.4, -1.0], diffuse=[0.4, 0.4, 0.4])
    for geom in spec.geoms:
        if geom.contype == 1:
            geom.rgba = [0.25, 0.45, 0.75, 1.0]
    return model, spec.compile()


def recorded_scene(path: str | Path, namespace: str = ""):
    """The obstacles of a recording's ``collision_objects`` at its end (a :class:`~manip_kin.core.scene.Scene`),
    or None when the recording has none; markers that are refused are left out."""
    from manip_kin.core.scene import Scene
    from manip_kin.pipeline.status import normalize_namespace
    from manip_kin.recording import read_messages
    from manip_kin.ros.wire.scene_messages import TOPIC, apply_marker_array

    scene, seen = Scene(), False
    for _topic, message, _log_ns, _publish_ns in read_messages(
        path, topics=[f"{normalize_namespace(namespace)}/{TOPIC}"]
    ):
        seen = True
        frame = message.markers[0].header.frame_id if message.markers else ""
        apply_marker_array(scene, message, frame)
    return scene if seen else None


def render_run(run, out_dir: str | Path, frames: int = 60, mesh_search_path: str = "", scene=None) -> list[Path]:
    """Draw ``frames`` joint states of ``run`` (a :class:`~manip_kin.viz.run_data.RunData`), evenly spread,
    with the obstacles of ``scene`` (see :func:`recorded_scene`; None: none).

    Writes ``render_start.png``, ``render_middle.png``, ``render_end.png`` and ``render.gif``
    (10 frames per second of the GIF) into ``out_dir``; returns their paths.

    Raises:
        InvalidArgumentError: the recording has no robot_description or no joint states.
        OperationError: offscreen rendering is not available (the message says what to install).
    """
    import mujoco
    from PIL import Image

    if not run.robot_description or not len(run.joint_time):
        raise InvalidArgumentError("--render needs a recording with robot_description and joint_states")
    model, mj_model = _scene_spec(run.robot_description, mesh_search_path, scene)
    data = mujoco.MjData(mj_model)
    columns = [run.joint_names.index(name) for name in model.joint_names if name in run.joint_names]
    if len(columns) != model.dof:
        missing = [name for name in model.joint_names if name not in run.joint_names]
        raise InvalidArgumentError(f"--render: the joint states lack {', '.join(missing)} of the recorded robot")
    addresses = [
        mj_model.jnt_qposadr[mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_JOINT, n)] for n in model.joint_names
    ]
    picks = np.unique(np.linspace(0, len(run.joint_time) - 1, max(frames, 2)).round().astype(int))
    camera = mujoco.MjvCamera()
    reach = float(
        np.sum([np.linalg.norm(j.origin[:3, 3]) for j in model.joints]) + np.linalg.norm(model.ee_offset[:3, 3])
    )
    camera.lookat[:] = [0.0, 0.0, 0.4 * reach]
    camera.distance, camera.azimuth, camera.elevation = 2.2 * reach, 135.0, -20.0
    renderer = _renderer(mj_model)
    images = []
    try:
        for index in picks:
            data.qpos[addresses] = run.joint_position[index, columns]
            mujoco.mj_kinematics(mj_model, data)
            renderer.update_scene(data, camera)
            images.append(renderer.render().copy())
    finally:
        renderer.close()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, image in (("start", images[0]), ("middle", images[len(images) // 2]), ("end", images[-1])):
        path = out_dir / f"render_{name}.png"
        Image.fromarray(image).save(path)
        paths.append(path)
    gif = out_dir / "render.gif"
    first, *rest = [Image.fromarray(image) for image in images]
    first.save(gif, save_all=True, append_images=rest, duration=100, loop=0)
    return paths + [gif]
