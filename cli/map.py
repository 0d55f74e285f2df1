"""`omninav map`: mapping a simulated world, and maps in the ROS map_server format.

  omninav map --world W -o maps/NAME   map a simulated world with slam (in one process), driving
                                       by frontier exploration (or --waypoints, or --route), save
                                       the map and compare it with the world's true occupancy
  omninav map save [-o maps/NAME]      the map being served on the bus (map_server, slam) to
                                       NAME.yaml + NAME.pgm, as ROS map_saver -f does
  omninav map show MAP.yaml -o map.png a picture of a map file, in map-frame metres

Each action is one entry of ACTIONS: (help, add_arguments(parser), main(args) -> int); without an
action the mapping's own arguments apply (an action's parser sets its own values over them).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.transforms import Affine2D

from ..schemas import MessageError, decode
from ..schemas.keys import DEFAULT_ROBOT, KeyLayout
from ..schemas.messages import OccupancyGrid
from ..services.map_server.mapio import (MODES, UNKNOWN_GREY, MapError, load_map, map_files, read_map_yaml,
                                          save_map)
from ..services.chassis.kinematics import DRIVES
from ..experiments.localize_eval import parse_waypoints
from ..services.runtime.params import parse_overrides
from ..parameters.declare import ParamError
from ..experiments.mapping import (MAPPING_ROUTES, MappingProgress, build_map, compare_with_truth,
                                   explored_share, slam_params_for)
from ..experiments.progress import Progress, progress
from ..sim.node import open_world
from ..sim.world import WorldError
from ..geometry.grid import GRID_OBSTACLE
from .introspect import ROUTER_HELP, CommandError, connect, key_expression, reports_errors
from .report import new_figure

UNKNOWN_SHADE = UNKNOWN_GREY / 255      # unknown cells drawn in the grey map_saver writes for them
MAX_DPI = 400.0


def describe(grid: OccupancyGrid) -> str:
    """Size, resolution, origin and how much is occupied, free and unknown, in one line."""
    info, data = grid.info, grid.data
    o = info.origin
    shares = [f"{100 * np.count_nonzero(mask) / max(1, data.size):.1f} % {name}"
              for name, mask in (("occupied", data > GRID_OBSTACLE), ("free", (data >= 0) & (data <= GRID_OBSTACLE)),
                                 ("unknown", data < 0))]
    return (f"{info.width} x {info.height} cells at {info.resolution:g} m/cell "
            f"({info.width * info.resolution:g} x {info.height * info.resolution:g} m), "
            f"origin x {o.x:g} m, y {o.y:g} m, yaw {o.theta:g} rad; " + ", ".join(shares))


# ---------------------------------------------------------------- omninav map save

def add_save_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("-o", "--output", default="map", metavar="PATH",
                        help="write PATH.yaml and its image PATH.pgm (default: map, as map_saver)")
    parser.add_argument("--key", default=KeyLayout(DEFAULT_ROBOT).robot("map"),
                        help="the key to `get` the map from (default %(default)s)")
    parser.add_argument("--mode", choices=MODES, default="trinary",
                        help="map_server mode of the saved file (default trinary; scale writes a PNG)")
    parser.add_argument("--force", action="store_true", help="overwrite existing files")
    parser.add_argument("--timeout", type=float, default=5.0, metavar="S",
                        help="wait this long for a reply (default 5 s)")
    parser.add_argument("--router", help=ROUTER_HELP)


def fetch_grid(router: str | None, key: str, timeout_s: float) -> OccupancyGrid:
    """The first OccupancyGrid that answers a `get` on key within timeout_s (raises CommandError)."""
    started = time.monotonic()
    session = connect(router, give_up_s=timeout_s)
    problems = []
    try:
        remaining = max(0.1, timeout_s - (time.monotonic() - started))
        for reply in session.get(key, timeout=remaining):
            if reply.ok is None:
                problems.append("error reply: " + reply.err.payload.to_bytes().decode(errors="replace"))
                continue
            reply_key = str(reply.ok.key_expr)
            try:
                return decode(reply.ok.payload.to_bytes(), OccupancyGrid, key=reply_key)
            except MessageError as exc:
                problems.append(f"malformed reply: {exc}")
    finally:
        session.close()
    if problems:
        raise CommandError("; ".join(problems))
    raise CommandError(f"no reply on {key} within {timeout_s:g} s (is a map being served? e.g. "
                       "`omninav run map_server --set yaml_filename=MAP.yaml`, or slam)")


@reports_errors
def main_save(args: argparse.Namespace) -> int:
    if args.timeout <= 0:
        raise CommandError("--timeout must be positive", 2)
    key = key_expression(args.key)
    if Path(args.output).is_dir():
        raise CommandError(f"-o {args.output} is a folder; give a file name without extension, "
                           f"e.g. {Path(args.output) / 'map'}", 2)
    files = map_files(args.output, args.mode)
    existing = [str(f) for f in files if f.exists()]
    if existing and not args.force:
        raise CommandError(f"{' and '.join(existing)} already exist{'s' if len(existing) == 1 else ''}; "
                           "choose another -o or add --force to overwrite")
    grid = fetch_grid(args.router, key, args.timeout)
    info = grid.info
    if info.width <= 0 or info.height <= 0 or grid.data.shape != (info.height, info.width):
        raise CommandError(f"the map on {key} is inconsistent: info says {info.width} x {info.height} "
                           f"cells, data holds {list(grid.data.shape)}; nothing written")
    try:
        yaml_path = save_map(grid, args.output, mode=args.mode)
    except OSError as exc:
        raise CommandError(f"-o {args.output}: cannot write ({exc})") from None
    print(f"wrote {yaml_path} and {files[1]} (mode {args.mode}): {describe(grid)}", flush=True)
    return 0


# ---------------------------------------------------------------- omninav map show

def add_show_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("map", help="the map's YAML file (ROS map_server format)")
    parser.add_argument("-o", "--output", required=True, metavar="PNG", help="the picture to write")


def grid_shades(data: np.ndarray) -> np.ndarray:
    """Grey levels 0..1 of cells: free white, occupied black, in between darker with occupancy;
    unknown map_saver's grey."""
    return np.where(data < 0, UNKNOWN_SHADE, 1.0 - np.clip(data, 0, 100) / 100.0)


def draw_grid(ax: Axes, grid: OccupancyGrid) -> None:
    """The grid's cells in the map frame (its origin's position and yaw honoured, cells not
    resampled), its origin as an arrow along the grid's x axis; the view fits the grid."""
    info = grid.info
    o = info.origin
    size = np.array([info.width, info.height]) * info.resolution
    grid_to_map = Affine2D().rotate(o.theta).translate(o.x, o.y)
    ax.imshow(grid_shades(grid.data), cmap="gray", vmin=0.0, vmax=1.0, origin="lower", interpolation="nearest",
              extent=(0.0, size[0], 0.0, size[1]), transform=grid_to_map + ax.transData, zorder=0)
    corners = grid_to_map.transform([[0, 0], [size[0], 0], [0, size[1]], size])
    ax.set_xlim(corners[:, 0].min(), corners[:, 0].max())
    ax.set_ylim(corners[:, 1].min(), corners[:, 1].max())
    reach = 0.08 * size.min()
    ax.annotate("", xy=(o.x + reach * np.cos(o.theta), o.y + reach * np.sin(o.theta)), xytext=(o.x, o.y),
                arrowprops={"arrowstyle": "->", "color": "tab:red", "linewidth": 1.5}, zorder=2)
    ax.plot([o.x], [o.y], "o", color="tab:red", markersize=4, zorder=2, label="grid origin (arrow: its x axis)")


def map_figure(grid: OccupancyGrid, title: str) -> Figure:
    """The picture; its dpi gives every cell at least one pixel (up to MAX_DPI), because a
    one-cell wall drawn smaller than a pixel can vanish."""
    fig, ax = new_figure()
    draw_grid(ax, grid)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    ax.set_title(title, fontsize=9)
    ax.grid(True, linewidth=0.3, alpha=0.5)
    box = ax.get_position()
    span_x, span_y = np.ptp(ax.get_xlim()), np.ptp(ax.get_ylim())
    metres_per_inch = max(span_x / (box.width * fig.get_figwidth()), span_y / (box.height * fig.get_figheight()))
    fig.set_dpi(float(np.clip(metres_per_inch / grid.info.resolution, fig.get_dpi(), MAX_DPI)))
    return fig


@reports_errors
def main_show(args: argparse.Namespace) -> int:
    try:
        grid = load_map(args.map)
        image = read_map_yaml(args.map).image
    except MapError as exc:
        raise CommandError(str(exc), 2) from None
    output = Path(args.output)
    if output.resolve() in (Path(args.map).resolve(), image.resolve()):
        raise CommandError(f"-o {args.output} is the map's own file; choose another", 2)
    fig = map_figure(grid, f"{args.map}\n{describe(grid)}")
    try:
        output.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(output, bbox_inches="tight", dpi=fig.get_dpi())    # savefig's default: the dpi at creation
    except (OSError, ValueError) as exc:
        raise CommandError(f"-o {args.output}: cannot write ({exc})", 2) from None
    print(f"wrote {output}: {describe(grid)}", flush=True)
    return 0


# ---------------------------------------------------------------- omninav map --world

def add_mapping_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--world", help="map this world: shipped world name or world file, e.g. sim/worlds/room.yaml")
    parser.add_argument("-o", "--output", metavar="PATH", help="with --world: write PATH.yaml and PATH.pgm")
    how = parser.add_mutually_exclusive_group()
    how.add_argument("--waypoints", metavar="'x,y;x,y;…'",
                     help="drive this route on the true pose instead of exploring")
    how.add_argument("--route", action="store_true",
                     help=f"drive the world's mapping route instead of exploring (there is one for "
                          f"{', '.join(MAPPING_ROUTES)})")
    parser.add_argument("--drive", choices=DRIVES, default="", help="drive (default: the world's)")
    parser.add_argument("--laps", type=int, default=1, help="with a route: times to drive it (default 1)")
    parser.add_argument("--max-time", type=float, default=1800.0, metavar="S",
                        help="stop after this much sim time even if unfinished (default 1800 s)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the sim, lidar and slam (default 0)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="override a slam parameter (e.g. particles=10)")
    parser.add_argument("--force", action="store_true", help="overwrite existing files")
    parser.add_argument("--quiet", action="store_true",
                        help="no progress (a bar of the share mapped on a terminal, else a line every 30 s of sim time)")


class MappingReport:
    """How far `map` is: a bar over the share of the reachable space mapped on a terminal, else a
    line every 30 s of sim time (a log reads those)."""

    def __init__(self, bar: Progress):
        self.bar, self.percent = bar, 0

    def __call__(self, report: MappingProgress) -> None:
        if not self.bar.drawn:
            print(f"map: {report.line()}", flush=True)
            return
        percent = round(100 * (report.mapped or 0.0))
        self.bar.advance(max(percent - self.percent, 0))
        self.percent = max(percent, self.percent)
        self.bar.note(f"sim {report.sim_s:.0f} s, {report.driven}")


@reports_errors
def main_mapping(args: argparse.Namespace) -> int:
    if not args.world or not args.output:
        raise CommandError("give --world W -o PATH to map a world, or an action: " + ", ".join(ACTIONS), 2)
    if args.laps < 1 or not args.max_time > 0:
        raise CommandError("--laps must be at least 1 and --max-time positive", 2)
    existing = [str(f) for f in map_files(args.output) if f.exists()]
    if existing and not args.force:
        raise CommandError(f"{' and '.join(existing)} already exist{'s' if len(existing) == 1 else ''}; "
                           "choose another -o or add --force to overwrite", 2)
    try:
        world = open_world(args.world)
        if args.route and world.name not in MAPPING_ROUTES:
            raise ValueError(f"--route: no mapping route for world {world.name!r} (there is one for "
                             f"{', '.join(MAPPING_ROUTES)}); give --waypoints or explore")
        route = parse_waypoints(args.waypoints) if args.waypoints else MAPPING_ROUTES[world.name] if args.route else None
        params = slam_params_for(world, parse_overrides(args.set), args.seed)
        with progress(100, "% mapped", args.quiet) as bar:
            result = build_map(args.world, route, args.drive, args.seed, params, args.laps, args.max_time,
                               progress=None if args.quiet else MappingReport(bar))
    except (WorldError, ParamError, ValueError) as exc:
        raise CommandError(str(exc), 2) from None
    if result.grid is None:
        raise CommandError("slam made no map (no scan reached it); nothing written")
    try:
        yaml_path = save_map(result.grid, args.output)
    except OSError as exc:
        raise CommandError(f"-o {args.output}: cannot write ({exc})") from None
    if route is None:
        how = f"explored {result.goals} frontiers" + ("" if result.finished else " (unfinished: frontiers left)")
    else:
        how = "drove the route" + ("" if result.finished else f" (unfinished: {result.laps} of {args.laps} laps)")
    print(f"{how} in {result.sim_s:.1f} s of sim time, {result.updates} slam updates, "
          f"{result.collisions} collisions", flush=True)
    print(f"wrote {yaml_path}: {describe(result.grid)}", flush=True)
    print(f"against the true occupancy of {world.name}: {compare_with_truth(result.grid, world).text()}; "
          f"{100 * explored_share(result.grid, world):.2f} % of the free space reachable from the start mapped",
          flush=True)
    return 0


# ---------------------------------------------------------------- the command

ACTIONS = {
    "save": ("save the map served on the bus (map_server format)", add_save_arguments, main_save),
    "show": ("draw a map file as a picture", add_show_arguments, main_show),
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_mapping_arguments(parser)
    parser.set_defaults(run=main_mapping, command_name="map")
    actions = parser.add_subparsers(dest="action", metavar="ACTION")
    for name, (help_text, add, run) in ACTIONS.items():
        sub = actions.add_parser(name, help=help_text, description=help_text)
        add(sub)
        sub.set_defaults(run=run, command_name=f"map {name}")


def main(args: argparse.Namespace) -> int:
    return args.run(args)
