"""Does an unloaded gear rattle in its play while cutting? (docs/validation.md)

Machines iso160 at its two poses with the shipped robot (friction, play and drives on, 0.25 mm dexels)
and prints, per joint, how often its gear changes flank and which share of the cutting cycles it
spends in the play, with the tool motion that joint's error makes where it does: the tool offset
``J_j (q_cmd,j - q_j)`` of joint j alone (J_j the Jacobian's column), band-passed to 2-40 Hz, its
largest peak-to-peak [µm] over each stay in the play (with 50 ms either side) and the dominant frequency [Hz] of its
spectrum over the cycles in the play. A joint whose gear never leaves its flank while cutting prints zeros.

    python scripts/gear_rattle_study.py [--robot ROBOT.toml] [--spacing-mm 0.25]

About 15 s per pose after the kernels are compiled.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.signal import butter, sosfiltfilt

from identify.records import markdown_table
from simulate.pipeline import MachiningJob, MachiningSettings, load_program, run_job
from simulate.robot.kinematics import jacobian
from simulate.robot.model import load_robot
from simulate.toolpath.placement import load_poses

ROOT = Path(__file__).resolve().parents[1]
DT = 0.002   # s, the NC cycle


def rows_for(robot, spacing: float) -> list[list[str]]:
    prog = load_program(ROOT / "data" / "programs" / "iso160.nc")
    rows = []
    for pose in load_poses(ROOT / "data" / "poses" / "iso160.json"):
        mo = run_job(MachiningJob(program=prog, robot=robot, placement=pose,
                                  settings=MachiningSettings(spacing=spacing, size=0)))
        contact = np.asarray(mo.result.joint_contact)
        force = np.linalg.norm(np.asarray(mo.result.steps.force), axis=1)
        cutting = force > 5.0
        jac = jacobian(robot, mo.trajectory.q)[:, :3]          # (N, 3, 6), base frame
        dq = np.asarray(mo.result.joint_error)
        sos = butter(4, [2.0, 40.0], btype="band", fs=1.0 / DT, output="sos")
        pad = int(0.05 / DT)
        for j in range(contact.shape[1]):
            c = contact[:, j]
            flips = int(np.count_nonzero((np.diff(c) != 0) & cutting[1:]))
            in_play = cutting & (c == 0)
            share = float(in_play.sum()) / max(1, int(cutting.sum()))
            pp, freq = 0.0, 0.0
            if in_play.sum() > 50:
                band = sosfiltfilt(sos, jac[:, :, j] * dq[:, j, None], axis=0)
                edges = np.flatnonzero(np.diff(np.r_[0, in_play.astype(np.int8), 0]))
                for a, b in zip(edges[::2], edges[1::2], strict=True):   # each stay in the play, with 50 ms around
                    x = band[max(0, a - pad):b + pad]
                    pp = max(pp, float(np.linalg.norm(x.max(axis=0) - x.min(axis=0))) * 1e6)
                spec = np.abs(np.fft.rfft(np.where(in_play[:, None], band, 0.0), axis=0)).sum(axis=1)
                f = np.fft.rfftfreq(len(band), DT)
                freq = float(f[1:][np.argmax(spec[1:])])
            rows.append([pose.name, f"A{j + 1}", str(flips), f"{100 * share:.1f}", f"{pp:.1f}", f"{freq:.1f}"])
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spacing-mm", type=float, default=0.25)
    ap.add_argument("--robot", default=str(ROOT / "data" / "robots" / "max100.toml"))
    a = ap.parse_args()
    rows = rows_for(load_robot(a.robot), a.spacing_mm * 1e-3)
    print("\n".join(markdown_table(["pose", "joint", "flank changes while cutting", "cycles in the play [%]",
                          "its tool motion in the play, peak to peak [µm]", "its frequency [Hz]"], rows)))


if __name__ == "__main__":
    main()
