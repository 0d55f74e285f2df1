"""The costmap's mover layer: where a tracked person will walk over the next seconds and the lane
they just walked cost, all of it alike; nothing behind them or for a standing one, and the way is never closed; the costmap forgets the
sweep when the person is gone; a plan in a corridor moves aside from a person coming head-on; and
the costmap service stamps the tracks it is sent, refuses tracks in the wrong frame and forgets
stale ones."""
import numpy as np
import pytest

from omninav.geometry.grid import world_to_cell
from omninav.geometry.movers import Movers
from omninav.schemas.messages import Clock, Header, MapMetaData, OccupancyGrid, Odometry, Pose2D, Tracks
from omninav.schemas.keys import KeyLayout
from omninav.services.costmap.costmap import Costmap
from omninav.services.costmap.layers import INSCRIBED_INFLATED_OBSTACLE, NO_INFORMATION
from omninav.services.costmap.mover_layer import sweep_costs
from omninav.services.costmap.node import CostmapNode, CostmapNodeParams
from omninav.services.costmap.params import MoverLayerParams, load_costmap_params
from omninav.services.global_planner.astar import GlobalPlanner
from omninav.services.map_server.mapio import save_map
from omninav.services.global_planner.params import GlobalPlannerParams
from omninav.services.runtime.merge import order_key
from omninav.services.runtime.node import NS_PER_S
from conftest import REPO

PARAMS = REPO / "compose" / "params"
MOVERS_FILES = (PARAMS / "costmap_common_params.yaml", PARAMS / "costmap_global_movers_params.yaml")
KEYS = KeyLayout("r1")


def person(x, y, vx, vy, radius=0.3) -> Movers:
    return Movers(np.array([[x, y]], float), np.array([[vx, vy]], float), np.array([radius]), np.zeros((1, 3)))


def free_grid(width_m: float, height_m: float, resolution: float = 0.05) -> MapMetaData:
    return MapMetaData(resolution=resolution, width=round(width_m / resolution), height=round(height_m / resolution),
                       origin=Pose2D(0.0, 0.0, 0.0))


def cost_at(costs: np.ndarray, info: MapMetaData, x: float, y: float) -> int:
    r, c = world_to_cell(info, x, y)
    return int(costs[r, c])


def test_a_walking_persons_way_and_the_lane_just_walked_cost_alike_and_nothing_around_a_standing_one():
    info, params = free_grid(12.0, 4.0), MoverLayerParams(prediction_time=4.0, behind_time=1.0, sweep_cost=180)
    out = np.full((info.height, info.width), NO_INFORMATION, np.uint8)
    box = sweep_costs(info, person(9.0, 2.0, -1.0, 0.0), 0.3, params, out)
    assert box is not None
    ahead = [cost_at(out, info, x, 2.0) for x in (8.5, 7.5, 6.5, 5.5, 4.5)]   # 0.5 … 4 s ahead (and the reach)
    assert ahead == [180] * 5 and 180 < INSCRIBED_INFLATED_OBSTACLE
    assert cost_at(out, info, 3.5, 2.0) == NO_INFORMATION                     # beyond the horizon and the reach
    assert cost_at(out, info, 10.5, 2.0) == 180                               # the lane just walked (1 s + the reach)
    assert cost_at(out, info, 10.9, 2.0) == NO_INFORMATION                    # and no further
    reach = 0.3 + 0.3 + params.margin
    assert cost_at(out, info, 7.0, 2.0 + reach - 0.06) > 0 and cost_at(out, info, 7.0, 2.0 + reach + 0.06) == NO_INFORMATION
    assert (out[out != NO_INFORMATION] < INSCRIBED_INFLATED_OBSTACLE).all()   # dear, never closed

    standing = np.full_like(out, NO_INFORMATION)
    assert sweep_costs(info, person(9.0, 2.0, -0.05, 0.0), 0.3, params, standing) is None
    assert (standing == NO_INFORMATION).all()


def movers_costmap(static: OccupancyGrid) -> Costmap:
    return Costmap(load_costmap_params(MOVERS_FILES, "global_costmap"), static)


def corridor(length=12.0, width=3.0, resolution=0.05) -> OccupancyGrid:
    info = free_grid(length, width, resolution)
    data = np.zeros((info.height, info.width), np.int8)
    data[:2, :], data[-2:, :] = 100, 100
    return OccupancyGrid(header=Header(frame_id="map"), info=info, data=data)


def test_the_costmap_forgets_a_sweep_once_the_person_has_gone():
    costmap = movers_costmap(corridor())
    costmap.update()
    before = costmap.costs.copy()
    costmap.set_movers(person(9.0, 1.5, -1.0, 0.0))
    costmap.update()
    assert (costmap.costs >= before).all() and (costmap.costs > before).sum() > 500
    costmap.set_movers(None)
    costmap.update()
    assert np.array_equal(costmap.costs, before)


def test_a_plan_moves_aside_from_a_person_coming_head_on_and_keeps_the_centre_without_one():
    costmap = movers_costmap(corridor(12.0, 3.0))
    planner = GlobalPlanner(GlobalPlannerParams(use_dijkstra=False))
    start, goal = (1.2, 1.5, 0.0), (10.8, 1.5, 0.0)
    costmap.update()
    alone = planner.plan(costmap.costs, costmap.info, start, goal)
    assert alone.ok and np.abs(alone.poses[:, 1] - 1.5).max() < 0.05
    costmap.set_movers(person(8.0, 1.5, -1.0, 0.0))      # walking the centre line towards the robot
    costmap.update()
    aside = planner.plan(costmap.costs, costmap.info, start, goal)
    assert aside.ok
    met = (aside.poses[:, 0] > 3.5) & (aside.poses[:, 0] < 7.5)   # where robot and person meet
    assert np.abs(aside.poses[met, 1] - 1.5).min() > 0.5          # the robot's centre beside the person's way
    assert (aside.poses[:, 1] > 0.3).all() and (aside.poses[:, 1] < 2.7).all()   # and clear of the walls


def tracks_message(t: float, x: float, y: float, vx: float, vy: float, frame="odom") -> Tracks:
    return Tracks(header=Header(stamp_ns=round(t * NS_PER_S), frame_id=frame), ids=np.array([7]),
                  states=np.array([[x, y, vx, vy]]), covariances=np.zeros((1, 4, 4)), radii=np.array([0.3]))


def feed(node, messages) -> None:
    index = {inp.key: i for i, inp in enumerate(node.inputs)}
    for _, i, msg in sorted(((order_key(m.header.stamp_ns, index[k], m.header.seq), index[k], m) for k, m in messages),
                            key=lambda item: item[0]):
        node.process(i, msg)


@pytest.fixture
def served(tmp_path):
    map_yaml = save_map(corridor(), tmp_path / "corridor")
    return CostmapNode(CostmapNodeParams(global_costmap_files=tuple(map(str, MOVERS_FILES)), map_file=str(map_yaml)))


def test_the_costmap_service_stamps_the_tracks_it_is_sent_and_forgets_stale_ones(served):
    odom = [message for t in np.arange(0.0, 3.0, 0.05) for message in (
        (KEYS.robot("odom"), Odometry(header=Header(stamp_ns=round(t * NS_PER_S), frame_id="odom"), pose=Pose2D(0.0, 0.0, 0.0))),
        (KEYS.sim("clock"), Clock(header=Header(stamp_ns=round(t * NS_PER_S)))))]
    tracks = [(KEYS.robot("tracks"), tracks_message(0.3, 8.0, 1.5, -1.0, 0.0)),
              (KEYS.robot("tracks"), tracks_message(0.35, 10.5, 1.5, 1.0, 0.0, frame="map"))]
    feed(served, odom[:40] + tracks)                              # up to t = 0.95 s
    glob = served.answer(KEYS.robot("costmap/global"), {})
    info = glob.info
    assert cost_at(glob.data, info, 6.5, 1.5) > 0                 # about 1 s ahead of the person then
    assert cost_at(glob.data, info, 11.0, 1.5) == cost_at(glob.data, info, 11.5, 1.5) == 0  # the map-frame track was refused
    assert served.counters[f"malformed/{KEYS.robot('tracks')}"] == 1
    feed(served, odom[40:])                                       # 2 s without tracks: more than tracks_timeout_s
    glob = served.answer(KEYS.robot("costmap/global"), {})
    assert cost_at(glob.data, info, 6.5, 1.5) == 0
