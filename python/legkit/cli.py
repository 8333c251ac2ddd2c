"""The ``legkit`` command."""

from __future__ import annotations

import argparse
import importlib
import sys

import numpy as np

import legkit as lk
from legkit._extras import MissingExtra, require
from legkit._help import HelpFormatter


def demo(_: argparse.Namespace) -> int:
    """The two quantities the balancing controller builds on [Moll 2006]: a composite's mass properties, and the
    joint angle that brings its centre of mass nearest a support line (a circle-line distance), checked by
    turning the composite through that angle."""
    module = lk.MassProperties.solid_box(0.25, [0.084, 0.084, 0.084], center=[0.0, 0.0, 0.042])
    arm = lk.MassProperties.solid_box(0.10, [0.3, 0.03, 0.03], center=[0.15, 0.0, 0.1])
    tip = lk.MassProperties.point(0.05, [0.3, 0.0, 0.1])
    total = sum([module, arm, tip], lk.MassProperties.zero())
    np.set_printoptions(precision=4, suppress=True)
    print("A 0.25 kg cube module carrying a 0.10 kg arm with a 0.05 kg tip mass, along +x (m, kg, kg m^2):")
    print(f"  mass {total.mass:.3f}, centre of mass {total.com}, principal moments about it {np.linalg.eigvalsh(total.inertia)}")

    # The module yaws about its vertical axis; the COM then moves on a circle, which the support line y = 0.12
    # (a polygon edge on the ground, along x) meets nearest where the arm points at it.
    axis_point, axis, line_point, line_direction = [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.12, 0.0], [1.0, 0.0, 0.0]
    theta, _ = lk.rotation_toward_line(axis_point, axis, total.com, line_point, line_direction)
    radius = float(np.hypot(*total.com[:2]))
    nearest = lk.circle_line(center=[0.0, 0.0, total.com[2]], normal=axis, radius=radius, line_point=line_point, line_direction=line_direction)

    def off_line(point: np.ndarray) -> float:
        """Distance (m) of a point to the support line."""
        return float(np.hypot(point[1] - line_point[1], point[2] - line_point[2]))

    c, s = np.cos(float(theta)), np.sin(float(theta))
    turned = total.transformed(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), np.zeros(3))
    print("\nBringing the COM nearest the support line y = 0.12 m, z = 0 by a yaw theta of the module:")
    print(f"  before: COM {off_line(total.com):.4f} m from the line")
    print(f"  theta = {np.degrees(float(theta)):.2f} deg (the circle-line distance: {nearest.distance:.4f} m at {nearest.circle_points[0]})")
    print(f"  after turning the composite by theta: COM at {turned.com}, {off_line(turned.com):.4f} m from the line")
    return 0


#: Subcommands implemented by an experiment module's own ``main(argv)``.
EXPERIMENTS = {
    "balance": ("legkit.experiments.balance", "distributed COM balancing of SuperBot trees (Moll et al. 2006)"),
    "strain": ("legkit.experiments.strain", "leg strain models and tripod body pose (Lin et al. 2003)"),
    "gait": ("legkit.experiments.gait", "stability and energy indices over a gait (Hardt & von Stryk 2002)"),
    "sweep": ("legkit.sweeps.cli", "sweeps of the balance experiment, locally or on Ray, into Parquet"),
    "tune": ("legkit.sweeps.tune", "tune the balance gain constants per scheme on random trees"),
}


def needs(command: str, options: list[str]) -> list[tuple[tuple[str, ...], str]]:
    """The optional modules an experiment's run needs, with their extra, checked before it starts (the sweeps
    check their own): figures and progress bars (plot), animations (viewer), gait optimisation (optimize)."""
    if command not in ("balance", "strain", "gait") or {"-h", "--help"} & set(options):
        return []
    wanted: list[tuple[tuple[str, ...], str]] = [(("matplotlib", "tqdm"), "plot")]
    optimize = command == "gait" and "--optimize" in options
    if optimize:
        wanted.append((("casadi",), "optimize"))
    if (command == "balance" or optimize) and "--no-animation" not in options:
        wanted.append((("meshcat", "PIL"), "viewer"))
    return wanted


def main(argv: list[str] | None = None) -> int:
    """Runs a command. What a user can cause without a bug (Ctrl-C, a file that cannot be written, a size that
    cannot be allocated, a value the library refuses, a numerical failure) ends it with one line on stderr, not a
    traceback."""
    argv = sys.argv[1:] if argv is None else list(argv)
    prog = f"legkit {argv[0]}" if argv and argv[0] in EXPERIMENTS else "legkit"
    try:
        return run(argv)
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    except MissingExtra as error:  # an optional dependency: the message says how to install it
        print(f"{prog}: {error}", file=sys.stderr)
        return 2
    except (OSError, MemoryError, RuntimeError) as error:
        print(f"{prog}: {type(error).__name__}: {error}", file=sys.stderr)
        return 1
    except (ValueError, TypeError) as error:  # a value the options' checks let through, refused by the library by name
        print(f"{prog}: error: {error}", file=sys.stderr)
        return 2


def run(argv: list[str]) -> int:
    if argv and argv[0] in EXPERIMENTS:
        module, _ = EXPERIMENTS[argv[0]]
        for modules, extra in needs(argv[0], argv[1:]):
            require(*modules, extra=extra)
        return importlib.import_module(module).main(argv[1:])
    parser = argparse.ArgumentParser(prog="legkit", description="Physics for legged and modular robots.", formatter_class=HelpFormatter)
    commands = parser.add_subparsers(dest="command", required=True, metavar="command")
    demo_help = "a composite mass and the yaw bringing its COM nearest a support line"
    commands.add_parser("demo", help=demo_help, formatter_class=HelpFormatter).set_defaults(run=demo)
    for name, (_, summary) in EXPERIMENTS.items():
        commands.add_parser(name, help=f"{summary}; legkit {name} --help for its options", add_help=False)
    args = parser.parse_args(argv)
    return args.run(args)


if __name__ == "__main__":
    sys.exit(main())
