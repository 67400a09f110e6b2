"""``brachycal demo``: the main job on the bundled example.

For now a forward-kinematics walkthrough: the model, the tool frames, the example joint log,
tool poses over time, and eq. (1) of the paper evaluated at the final pose.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from brachycal.data import read_joint_log, write_pose_table
from brachycal.files import bundled
from brachycal.model import LEFT_FLANGE, NEEDLE_TIP, PROBE_TIP, RIGHT_FLANGE, US_IMAGE, Robot
from brachycal.se3 import inverse, transform_points

HELP = "walk through the bundled example (forward kinematics of the tool frames)"
#: Pixel spacing of the paper's scanner (mm/pixel), CONVENTIONS.md.
SPACING_MM = 0.19


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("demo", help=HELP, description=HELP + ".")
    parser.add_argument(
        "--out", default="demo_output", metavar="DIR", help="folder for the outputs (default demo_output)"
    )
    parser.set_defaults(run=run)


def _mm(p: np.ndarray) -> str:
    return "(" + ", ".join(f"{x:8.2f}" for x in np.asarray(p) * 1e3) + ")"


def run(args: argparse.Namespace) -> int:
    robot = Robot.load()
    print("brachycal demo: forward kinematics of the SDA10F tool frames on the bundled example\n")
    print(f"model      {robot.source}")
    print(f"           {robot.nq} controlled axes: torso_joint_b1, arm_left_joint_1_s..7_t, arm_right_joint_1_s..7_t")
    print("           (the vendor's torso_joint_b2 only mirrors b1 and is a fixed joint here)")
    print("tool frames, nominal placeholders until calibrated (xyz in mm in the parent frame):")
    for frame in (NEEDLE_TIP, PROBE_TIP, US_IMAGE):
        parent, T = robot.tool_transform(frame)
        print(f"           {frame:10s} on {parent:22s} {_mm(T[:3, 3])}")

    log_path = bundled("examples", "joint_log.csv")
    log = read_joint_log(log_path, robot)
    print(f"\njoint log  {log_path}: {len(log)} samples over {log.time[-1] - log.time[0]:.2f} s")

    frames = [NEEDLE_TIP, PROBE_TIP]
    start = time.perf_counter()
    poses = robot.fk_frames(frames, log.q)
    batch_s = time.perf_counter() - start
    reference = robot.fk_frames_loop(frames, log.q)
    agreement = float(np.abs(poses - reference).max())

    print("tool tips in base_link (mm):")
    for t in (0.0, 5.0, 10.0):
        i = int(np.argmin(np.abs(log.time - t)))
        print(
            f"  t = {log.time[i]:5.2f} s   needle_tip {_mm(poses[0, i, :3, 3])}   probe_tip {_mm(poses[1, i, :3, 3])}"
        )

    q = log.q[-1]
    T_R_ER, T_R_EL = robot.fk(RIGHT_FLANGE, q), robot.fk(LEFT_FLANGE, q)
    _, T_ER_Ntip = robot.tool_transform(NEEDLE_TIP)
    _, T_EL_Ptip = robot.tool_transform(PROBE_TIP)
    _, T_Ptip_I = robot.tool_transform(US_IMAGE)
    p_R_Ntip = transform_points(T_R_ER, T_ER_Ntip[:3, 3])
    p_I_Ntip = transform_points(inverse(T_R_EL @ T_EL_Ptip @ T_Ptip_I), p_R_Ntip)
    u, v = p_I_Ntip[:2] * 1e3 / SPACING_MM
    print("\neq. (1) at the final pose: where the image sees the needle tip")
    print("  p_I = inv(T_R_EL @ T_EL_Ptip @ T_Ptip_I) @ T_R_ER @ p_ER_Ntip")
    print(
        f"      = pixel (u, v) = ({u:.1f}, {v:.1f}) at {SPACING_MM} mm/pixel, "
        f"{abs(p_I_Ntip[2]) * 1e3:.3f} mm from the image plane"
    )

    print(
        f"\nbatch FK   {len(log)} samples x {len(frames)} frames in {batch_s * 1e3:.1f} ms; "
        f"agrees with Pinocchio's per-sample loop to {agreement:.1e} m"
    )

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    table = write_pose_table(out / "poses.csv", log.time, frames, poses, force=True)
    urdf = robot.write_urdf(out / "sda10f_nominal.urdf", force=True)
    print(f"wrote      {table} (pose table) and {urdf} (URDF, loadable from there)")
    print("\nnext: brachycal fk LOG --frames needle_tip,probe_tip --out poses.csv")
    print("      brachycal calibrate examples/session_exact --out result.json   (brachycal --help)")
    return 0
