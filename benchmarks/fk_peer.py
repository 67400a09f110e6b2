"""The plain way to compute a pose table, the peer ``brachycal fk`` is measured against.

``genfromtxt`` reads the whole log, a per-row loop calls Pinocchio (``forwardKinematics`` and
``updateFramePlacement`` per frame), and each row is formatted and written as ``brachycal fk``
writes it. Run by ``fk_scale.py`` as a subprocess: ``fk_peer.py LOG OUT FRAME,FRAME``.
"""

from __future__ import annotations

import sys

import numpy as np
import pinocchio as pin

from brachycal.model import Robot


def main(log: str, out: str, frames: list[str]) -> None:
    robot = Robot.load()
    table = np.genfromtxt(log, delimiter=",", names=True)
    Q = robot.to_pinocchio(np.column_stack([table[name] for name in robot.joint_names]))
    model, data = robot.model, robot.model.createData()
    ids = [model.getFrameId(f) for f in frames]
    with open(out, "w") as handle:
        handle.write("time,frame,x,y,z,qx,qy,qz,qw\n")
        for t, q in zip(table["time"], Q, strict=True):
            pin.forwardKinematics(model, data, q)
            for frame, fid in zip(frames, ids, strict=True):
                T = pin.updateFramePlacement(model, data, fid)
                x, y, z = T.translation
                qx, qy, qz, qw = pin.Quaternion(T.rotation).coeffs()
                if qw < 0:  # the pose table's convention: qw >= 0
                    qx, qy, qz, qw = -qx, -qy, -qz, -qw
                handle.write(f"{t:.9f},{frame},{x:.9f},{y:.9f},{z:.9f},{qx:.12f},{qy:.12f},{qz:.12f},{qw:.12f}\n")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], sys.argv[3].split(","))
