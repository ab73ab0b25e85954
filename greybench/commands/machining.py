"""``greybench machine`` (paper 3.3-3.7, Figure 4): :func:`simulate.run.machine_part`."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from greybench import options as o
from greybench.support import print_summary, progress, resolve_robot, show, warn
from simulate import defaults
from simulate.run import MACHINING_UNITS, cutter_from_robot, machine_part, machining_job

__all__ = ["COMMANDS", "cutter_from_robot"]  # the robot file's cutter, named here for the tests


def machine(
    program: o.Program,
    pose: o.Pose,
    out_dir: Annotated[Path, typer.Option("--out", help="Output folder for the virtual workpiece (npz, m), PLY/GLB, "
                                                        "PNG, scan.csv (m).")],
    robot: o.Robot = "max100",
    name: o.PoseName = None,
    ideal: Annotated[bool, typer.Option("--ideal", help="No deflection, no tracking error, no backlash.")] = False,
    spacing: o.Spacing = o.PART_SPACING_MM,
    no_deflection: Annotated[bool, typer.Option("--no-deflection", help="Switch off the robot deflection.")] = False,
    no_friction: Annotated[bool, typer.Option("--no-friction", help="Servo without joint friction (its tracking "
                                                                    "error stays) [-].")] = False,
    no_tracking: Annotated[bool, typer.Option("--no-tracking", help="Switch off the servo tracking error "
                                                                    "[-].")] = False,
    no_switching: Annotated[bool, typer.Option("--no-switching", help="No gear backlash (the switching-point "
                                                                      "effect), no switching bits.")] = False,
    material: Annotated[str, typer.Option("--material", help="Material in data/materials.toml (coefficients "
                                                             "N/mm^2, N/mm).")] = defaults.MATERIAL,
    stock: Annotated[Path | None, typer.Option("--stock", help="Stock description JSON [m or mm] (default: "
                                                               "<program>.stock.json).")] = None,
    spindle_rpm: Annotated[float | None, typer.Option("--spindle", help="Spindle speed [rev/min] (default: program "
                                                                        "S word).")] = None,
    variable: Annotated[str, typer.Option("--color", help="Variable for the colour map (deflection [m], force [N], "
                                                          "...).")] = "deflection",
    size: Annotated[int | None, typer.Option("--size", help="Test-piece size [mm] (160 or 320) for the virtual CMM's "
                                                            "scan.csv (default: the stock JSON's size_mm; neither: no "
                                                            "scan).")] = None,
    probe_spacing: o.ProbeSpacing = o.PROBE_SPACING_MM,
    setup: o.Setup = None,
    require_units: o.RequireUnits = False,
    as_json: o.Json = False,
) -> None:
    """Simulate machining with robot deflection and tracking error in the loop (paper Figure 4).

    The cutter is the robot file's [tool] (the robot carries spindle and tool); with --setup, each
    tool the program loads (T, M6) is cut with the tool table's entry (docs/gcode.md), at the S in
    force. When the stock is an ISO 10791-7 test piece (its JSON names size_mm, or --size), the
    virtual CMM probes the result and OUT gets scan.csv (feature,x,y,z; workpiece frame, m).
    """
    job = machining_job(program, resolve_robot(robot), pose, name, ideal=ideal, spacing_mm=spacing,
                        no_deflection=no_deflection, no_friction=no_friction, no_switching=no_switching,
                        no_tracking=no_tracking, material=material, stock=stock, spindle_rpm=spindle_rpm, size=size,
                        probe_spacing_mm=probe_spacing, setup=setup, require_units=require_units)
    # progress and warnings on stderr also with --json (stdout carries only the JSON object)
    info = machine_part(job, out_dir, variable, progress=progress, on_warnings=warn)
    units = MACHINING_UNITS

    def rows() -> dict:
        table = {f"{k} ({units[k]})" if k in units else k: v for k, v in info.items() if k != "tools"}
        for u in info["tools"]:
            name = f"T{u['tool']}" if u["tool"] else "robot's tool"
            rpm = ", ".join(f"{r:g}" for r in u["spindle_rpm"])
            table[f"{name}: {u['diameter'] * 1e3:g} mm, {u['flutes']} flutes, {rpm} rev/min"] = (
                f"removed {u['removed_volume'] * 1e9:.6g} mm^3, peak force {u['peak_force']:.6g} N")
        return table

    show(as_json, info, lambda: print_summary(f"machining {program.name}", rows()))


COMMANDS = {"machine": machine}
