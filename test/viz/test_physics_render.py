"""MuJoCo's offscreen renderer draws a recorded run (``manip_kin plot --render``): PNGs and a GIF of the arm."""

import numpy as np
from PIL import Image
from test_recording_tf import write_run

from manip_kin.viz.physics_render import HEIGHT, WIDTH, render_run
from manip_kin.viz.run_data import load_run


def test_render_draws_the_recorded_arm_moving_into_pngs_and_a_gif(tmp_path):
    recording = tmp_path / "run.mcap"
    write_run(recording, "genova7")  # the arm moving between two configurations, with its robot_description
    paths = render_run(load_run(recording), tmp_path / "out", frames=4)
    assert [p.name for p in paths] == ["render_start.png", "render_middle.png", "render_end.png", "render.gif"]
    start, end = (np.asarray(Image.open(p).convert("RGB"), dtype=float) for p in (paths[0], paths[2]))
    assert start.shape == (HEIGHT, WIDTH, 3)
    arm = np.abs(start[..., 2] - start[..., 0]) > 40  # the arm is drawn blue on a grey floor
    assert 200 < arm.sum() < 0.5 * arm.size
    assert np.abs(start - end).mean() > 0.5  # the arm moved between the first and the last frame
    assert Image.open(paths[3]).n_frames == 4
