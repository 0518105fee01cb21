"""The comparison workload as a VMAS scenario (VMAS 1.5.x, torch CPU).

Same scene as ``benchmarks.workloads`` workload (a): N copters (``n_agents``, default 10) of radius
0.15 m in a 3 m × 4 m box (VMAS centres its world at the origin: the box is [−1.5, 1.5] × [−2, 2],
``x_semidim``/``y_semidim`` keep agents inside), 4 straight walls (``Line`` landmarks on the box
edges), a 4-ray lidar per agent (``n_rays``; 0°, 90°, 180°, 270° from its heading, 3 m range) that
hits walls and the other agents, and the pairwise centre distances (computed once per step for all
agents and sliced per agent). Observation of an agent: [lidar (4), own distances to all agents (N),
cos ψ, sin ψ, vx, vy]. Rewards are zero; episodes never end.

What differs from finkensim's kinematic update: VMAS integrates its own force-based physics
(``HolonomicWithRotation``: action = force x, force y, torque; drag; collision forces between every
pair of colliding entities), which is what a VMAS user runs. :func:`controller` turns observations
into actions with the same reactive rule as workload (a) (turn toward the more open side, slow down
near obstacles and neighbours), as a force toward the commanded velocity and a torque toward the
commanded yaw rate, so the step includes observation → action like the other implementations.
"""
from __future__ import annotations

import torch
from vmas.simulator.core import Agent, Landmark, Line, Sphere, World
from vmas.simulator.dynamics.holonomic_with_rot import HolonomicWithRotation
from vmas.simulator.scenario import BaseScenario
from vmas.simulator.sensors import Lidar
from vmas.simulator.utils import ScenarioUtils

WIDTH = 3.0
LENGTH = 4.0
RADIUS = 0.15
MAX_RANGE = 3.0
DT = 0.05
# controller constants: the same as benchmarks.workloads.CompareParams
V_MAX = 0.5
K_TURN = 1.0
SWIRL = 0.3
STOP = 0.3
SLOW = 1.0
SEP = 0.5
GAIN = 4.0


class Scenario(BaseScenario):
    def make_world(self, batch_dim: int, device: torch.device, **kwargs):
        self.n_agents = kwargs.pop("n_agents", 10)
        n_rays = kwargs.pop("n_rays", 4)
        ScenarioUtils.check_kwargs_consumed(kwargs)
        world = World(batch_dim, device, dt=DT, substeps=1, x_semidim=WIDTH / 2 - RADIUS,
                      y_semidim=LENGTH / 2 - RADIUS)
        for i in range(self.n_agents):
            agent = Agent(name=f"agent_{i}", shape=Sphere(radius=RADIUS), collide=True, rotatable=True,
                          dynamics=HolonomicWithRotation(), u_range=[2.0, 2.0, 2.0],
                          sensors=[Lidar(world, angle_start=0.0, angle_end=2 * torch.pi, n_rays=n_rays,
                                         max_range=MAX_RANGE, entity_filter=lambda e: True, render=False)])
            world.add_agent(agent)
        self._index = {a.name: i for i, a in enumerate(world.agents)}
        self.walls = []
        for i, (length, x, y, rot) in enumerate([(WIDTH, 0.0, -LENGTH / 2, 0.0), (WIDTH, 0.0, LENGTH / 2, 0.0),
                                                 (LENGTH, -WIDTH / 2, 0.0, torch.pi / 2),
                                                 (LENGTH, WIDTH / 2, 0.0, torch.pi / 2)]):
            wall = Landmark(name=f"wall_{i}", collide=True, shape=Line(length=length))
            wall.wall_pose = (x, y, rot)
            world.add_landmark(wall)
            self.walls.append(wall)
        self._pairwise = None
        return world

    def reset_world_at(self, env_index: int | None = None):
        B = self.world.batch_dim if env_index is None else 1
        dev = self.world.device
        for wall in self.walls:
            x, y, rot = wall.wall_pose
            wall.set_pos(torch.tensor([x, y], device=dev, dtype=torch.float32).expand(B, 2).clone()
                         if env_index is None else torch.tensor([x, y], device=dev, dtype=torch.float32),
                         batch_index=env_index)
            wall.set_rot(torch.tensor([rot], device=dev, dtype=torch.float32).expand(B, 1).clone()
                         if env_index is None else torch.tensor([rot], device=dev, dtype=torch.float32),
                         batch_index=env_index)
        gen = torch.Generator().manual_seed(0 if env_index is None else int(env_index))
        for agent in self.world.agents:
            u = torch.rand((B, 2), generator=gen)
            pos = torch.stack([(u[:, 0] - 0.5) * (WIDTH - 2 * RADIUS), (u[:, 1] - 0.5) * (LENGTH - 2 * RADIUS)], -1)
            rot = (torch.rand((B, 1), generator=gen) * 2 - 1) * torch.pi
            if env_index is not None:
                pos, rot = pos[0], rot[0]
            agent.set_pos(pos.to(dev), batch_index=env_index)
            agent.set_rot(rot.to(dev), batch_index=env_index)

    def observation(self, agent: Agent):
        if agent is self.world.agents[0]:  # pairwise distances once per step, shared by all agents
            pos = torch.stack([a.state.pos for a in self.world.agents], dim=1)  # (B, N, 2)
            self._pairwise = torch.linalg.vector_norm(pos[:, :, None, :] - pos[:, None, :, :], dim=-1)
        i = self._index[agent.name]
        rot = agent.state.rot
        return torch.cat([agent.sensors[0].measure(), self._pairwise[:, i], torch.cos(rot), torch.sin(rot),
                          agent.state.vel], dim=-1)

    def reward(self, agent: Agent):
        return torch.zeros(self.world.batch_dim, device=self.world.device)


def controller(obs: list[torch.Tensor], n_agents: int) -> list[torch.Tensor]:
    """Actions from observations: the reactive rule of workload (a) as force/torque commands."""
    actions = []
    for i, o in enumerate(obs):
        s = o[:, :4]
        d = o[:, 4:4 + n_agents].clone()
        d[:, i] = float("inf")
        nearest = d.min(dim=1).values
        c, sn = o[:, 4 + n_agents], o[:, 5 + n_agents]
        vel = o[:, 6 + n_agents:8 + n_agents]
        w = K_TURN * (s[:, 1] - s[:, 3]) + SWIRL
        speed = V_MAX * torch.clamp((s[:, 0] - STOP) / SLOW, 0.1, 1.0) * torch.clamp(nearest / SEP, 0.2, 1.0)
        fx = GAIN * (speed * c - vel[:, 0])
        fy = GAIN * (speed * sn - vel[:, 1])
        actions.append(torch.stack([fx, fy, GAIN * w * 0.1], dim=-1))
    return actions
