"""The force-induced tool offset and the Cartesian stiffness per pose (docs/validation.md).

For each pose of the shipped pose files (iso160: near, far_rotated; iso320: pose1..pose4) it machines
the test piece with friction and play switched off (drives and deflection on: the offset from the
command is then the process force through the robot's compliance plus a servo lag of under 1 µm) and
prints as markdown, per pose:

- the softest and stiffest translational Cartesian stiffness at the tool [N/µm] (eigenvalues of the
  inverse of ``J K_total^-1 J^T``'s translational block) at the first cutting step;
- the mean cutting force magnitude [N] and the mean tool offset magnitude [µm] over the steps that
  cut (|F| > 5 N), and the mean of the closed form ``|J K_total^-1 J^T F|`` [µm] over the same steps
  (the loop's one-step lag: the force of the step before);
- the largest of both [µm].

    python scripts/force_offset_study.py [--spacing-mm 0.25] [--sizes 160 320]

About 15 s per iso160 pose and 40 s per iso320 pose after the kernels are compiled.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from identify.records import markdown_table
from simulate.pipeline import Components, MachiningJob, MachiningSettings, load_program, run_job
from simulate.robot.kinematics import jacobian
from simulate.robot.model import load_robot
from simulate.robot.stiffness import joint_compliance
from simulate.toolpath.placement import load_poses

ROOT = Path(__file__).resolve().parents[1]


def study(robot, size: int, spacing: float) -> list[list[str]]:
    prog = load_program(ROOT / "data" / "programs" / f"iso{size}.nc")
    rows = []
    for pose in load_poses(ROOT / "data" / "poses" / f"iso{size}.json"):
        t0 = time.perf_counter()
        mo = run_job(MachiningJob(program=prog, robot=robot, placement=pose,
                                  components=Components(friction=False, switching=False),
                                  settings=MachiningSettings(spacing=spacing, size=0)))
        st = mo.steps
        F = np.asarray(st.force)
        cut = np.flatnonzero(np.linalg.norm(F, axis=1) > 5.0)
        cut = cut[cut > 0]
        R = pose.T[:3, :3]
        Jb = jacobian(robot, mo.trajectory.q[cut - 1])[:, :3]
        J = np.einsum("ji,njk->nik", R, Jb)   # workpiece frame
        kinv = joint_compliance(robot)
        want = np.einsum("nij,j,nkj,nk->ni", J, kinv, J, F[cut - 1])
        got = st.tool_offset()[cut]
        C0 = Jb[0] @ np.diag(kinv) @ Jb[0].T
        k = np.linalg.eigvalsh(np.linalg.inv(C0)) * 1e-6
        rows.append([f"iso{size} {pose.name}", f"{k.min():.3f}", f"{k.max():.2f}",
                     f"{np.linalg.norm(F[cut], axis=1).mean():.1f}",
                     f"{np.linalg.norm(got, axis=1).mean() * 1e6:.1f}",
                     f"{np.linalg.norm(want, axis=1).mean() * 1e6:.1f}",
                     f"{np.linalg.norm(got, axis=1).max() * 1e6:.1f}",
                     f"{np.linalg.norm(want, axis=1).max() * 1e6:.1f}", f"{time.perf_counter() - t0:.0f}"])
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spacing-mm", type=float, default=0.25)
    ap.add_argument("--sizes", type=int, nargs="+", default=[160, 320])
    ap.add_argument("--robot", default=str(ROOT / "data" / "robots" / "max100.toml"))
    a = ap.parse_args()
    robot = load_robot(a.robot)
    rows = []
    for size in a.sizes:
        rows += study(robot, size, a.spacing_mm * 1e-3)
    print("\n".join(markdown_table(["pose", "k min [N/µm]", "k max [N/µm]", "mean |F| [N]", "mean offset [µm]",
                          "mean |C F| [µm]", "max offset [µm]", "max |C F| [µm]", "run [s]"], rows)))


if __name__ == "__main__":
    main()
