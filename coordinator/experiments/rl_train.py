"""Train one policy shared by every taxi on :class:`coordinator.rl_env.FleetParallelEnv`, and compare it with greedy.

The RL library is Stable-Baselines3 with its contrib package's maskable PPO,
fed through SuperSuit, which turns the PettingZoo parallel environment into a
vector environment with one slot per taxi, so one network is trained on every
taxi's experience (parameter sharing), with the shared team reward (minus the
requests waiting each minute).  The network reads :class:`FleetParallelEnv`'s
observation vector with its action mask appended, and the mask also limits
the policy's choice to the slots that exist (:class:`ObservedMasks` hands it
to maskable PPO).  ``pip install 'surge[rl]'``.

Training episodes place the fleet by the environment's drawn seeds (1000 and
up) on ``train_date``; the learning curve and the final comparison play the
``eval_seeds`` (500 and up: neither drawn in training nor the test protocol's
0-24) on ``eval_dates``, a week later, so the policy is judged on demand it
never trained on.  Run it with ``examples/rl_shared_policy.py``.
"""

from __future__ import annotations

import datetime as dt
import json
import logging
import time
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

import gymnasium

try:
    import supersuit as ss
    import torch
    from sb3_contrib import MaskablePPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.utils import set_random_seed
    from stable_baselines3.common.vec_env import VecEnvWrapper, VecNormalize
except ImportError as exc:  # pragma: no cover - exercised only without the extra
    raise ImportError("coordinator.experiments.rl_train needs Stable-Baselines3, sb3-contrib and SuperSuit: pip install 'surge[rl]'") from exc

from agents.greedy import greedy_controls
from city.fingerprint import machine
from city.logs import steps
from coordinator.experiments.analysis import bootstrap_ci
from coordinator.rl_env import EnvConfig, FleetParallelEnv

Policy = Callable[[FleetParallelEnv, dict], dict]


@dataclass(frozen=True)
class TrainConfig:
    """What to train on, for how long, and how the policy is judged."""

    scenario: str = "synthetic"
    taxis: int = 20
    hour: int = 19
    minutes: int = 30
    train_date: str = "2022-08-02"
    eval_dates: tuple[str, ...] = ("2022-08-09",)
    eval_seeds: tuple[int, ...] = tuple(range(500, 510))
    timesteps: int = 300_000
    eval_every: int = 30_000
    seed: int = 0
    threads: int = 1
    minibatches: int = 4
    ppo: dict = field(default_factory=lambda: {
        "n_steps": 150, "n_epochs": 5, "learning_rate": 3e-4,
        "gamma": 0.95, "ent_coef": 0.01, "policy_kwargs": {"net_arch": [64, 64]},
    })

    def env(self, date: str) -> EnvConfig:
        return EnvConfig(scenario=self.scenario, date=date, hour=self.hour, minutes=self.minutes, taxis=self.taxis)


def flat(obs: dict) -> np.ndarray:
    """One agent's observation vector with its action mask appended, as the policy network reads it."""
    return np.concatenate([obs["observation"], obs["action_mask"].astype(np.float32)])


def _flat_space(space: gymnasium.spaces.Dict) -> gymnasium.spaces.Box:
    obs, mask = space["observation"], space["action_mask"]
    low = np.concatenate([obs.low, np.zeros(mask.shape, np.float32)])
    high = np.concatenate([obs.high, np.ones(mask.shape, np.float32)])
    return gymnasium.spaces.Box(low, high, dtype=np.float32)


class ObservedMasks(VecEnvWrapper):
    """Answers maskable PPO's ``action_masks`` from the last observations, whose tail is the mask (:func:`flat`)."""

    def __init__(self, venv, slots: int) -> None:
        super().__init__(venv)
        self.slots = slots
        self.last: np.ndarray | None = None

    def reset(self) -> np.ndarray:
        self.last = self.venv.reset()
        return self.last

    def step_wait(self):
        obs, rewards, dones, infos = self.venv.step_wait()
        self.last = obs
        return obs, rewards, dones, infos

    def has_attr(self, attr_name: str) -> bool:
        return attr_name == "action_masks" or self.venv.has_attr(attr_name)

    def env_method(self, method_name: str, *args, indices=None, **kwargs) -> list:
        if method_name != "action_masks":
            return self.venv.env_method(method_name, *args, indices=indices, **kwargs)
        assert self.last is not None, "reset() first"
        return list(self.last[:, -self.slots :] > 0.5)


def vector_env(cfg: TrainConfig) -> VecNormalize:
    """The training environment: every taxi is one slot of an SB3 vector env.

    One copy of the parallel env: SuperSuit's copies are clones whose seed
    streams would place their fleets alike.
    """
    env = FleetParallelEnv(cfg.env(cfg.train_date))
    env = ss.observation_lambda_v0(env, lambda obs, _space: flat(obs), lambda space: _flat_space(space))
    slots = env.action_space(env.possible_agents[0]).n
    vec = ss.concat_vec_envs_v1(ss.pettingzoo_env_to_vec_env_v1(env), 1, num_cpus=0, base_class="stable_baselines3")
    with warnings.catch_warnings():
        # SuperSuit's vector env answers no get_attr("render_mode"); SB3 then warns and takes None, which is right here.
        warnings.filterwarnings("ignore", message="The `render_mode` attribute is not defined")
        return VecNormalize(ObservedMasks(vec, slots), norm_obs=False, norm_reward=True, gamma=cfg.ppo.get("gamma", 0.99))


def model_policy(model: MaskablePPO) -> Policy:
    """Every taxi's most likely action under the shared network, among the slots that exist."""

    def act(env: FleetParallelEnv, obs: dict) -> dict:
        batch = np.stack([flat(obs[a]) for a in env.agents])
        masks = np.stack([obs[a]["action_mask"] > 0 for a in env.agents])
        actions, _ = model.predict(batch, deterministic=True, action_masks=masks)
        return dict(zip(env.agents, (int(a) for a in actions)))

    return act


def greedy_policy(env: FleetParallelEnv, _obs: dict) -> dict:
    """``surge evaluate``'s greedy, played through the environment's actions."""
    joint = greedy_controls(env.episode.city, env.sim.observe())
    return {a: env.action_of(a, int(joint[i])) for i, a in enumerate(env.agents)}


def stay_policy(env: FleetParallelEnv, _obs: dict) -> dict:
    """Free taxis never move: the cost of doing nothing."""
    return {a: 0 for a in env.agents}


def play(cfg: TrainConfig, policy: Policy) -> list[dict]:
    """The total cost of ``policy`` on every evaluation instance (date, seed)."""
    out = []
    for date in cfg.eval_dates:
        env = FleetParallelEnv(cfg.env(date))
        for seed in cfg.eval_seeds:
            obs, _ = env.reset(seed=seed)
            while env.agents:
                obs, *_ = env.step(policy(env, obs))
            out.append({"date": date, "seed": seed, "total_cost": env.total_cost})
    return out


class _Curve(BaseCallback):
    """Plays the evaluation instances every ``every`` agent-steps and records the mean total cost."""

    def __init__(self, cfg: TrainConfig, log: Callable[[str], None]) -> None:
        super().__init__()
        self.cfg, self.log, self.points, self.next_at, self.t0 = cfg, log, [], 0, time.perf_counter()
        self.bar, self.counted = steps(cfg.timesteps, "agent-step", "train PPO"), 0

    def record(self) -> None:
        costs = [r["total_cost"] for r in play(self.cfg, model_policy(self.model))]
        point = {"timesteps": int(self.num_timesteps), "seconds": round(time.perf_counter() - self.t0, 1),
                 "mean_total_cost": float(np.mean(costs))}
        self.points.append(point)
        self.log(f"{point['timesteps']:>9} agent-steps  {point['seconds']:>7.1f} s  mean total cost {point['mean_total_cost']:.1f}")

    def _on_step(self) -> bool:
        self.bar.update(self.num_timesteps - self.counted)
        self.counted = self.num_timesteps
        if self.num_timesteps >= self.next_at:
            self.record()
            self.next_at = self.num_timesteps + self.cfg.eval_every
        return True


def paired_summary(mine: list[dict], other: list[dict]) -> dict:
    """Mean difference (policy - other) over the instances, its 95 % bootstrap CI, and the policy's wins."""
    diff = np.array([a["total_cost"] - b["total_cost"] for a, b in zip(mine, other)], dtype=float)
    lo, hi = bootstrap_ci(diff)
    return {"mean_diff": float(diff.mean()), "ci95": [lo, hi], "wins": int((diff < 0).sum()),
            "ties": int((diff == 0).sum()), "n": int(diff.size)}


def train(cfg: TrainConfig, command: str = "", log: Callable[[str], None] = logging.getLogger(__name__).info) -> tuple[MaskablePPO, dict]:
    """Train the shared policy; the results document (curve, final costs, paired differences against greedy and stay)."""
    torch.set_num_threads(cfg.threads)
    set_random_seed(cfg.seed)
    vec = vector_env(cfg)
    # Seeded through set_random_seed, not PPO(seed=...): SuperSuit's SB3 wrapper has no VecEnv.seed.
    batch_size = max(2, cfg.ppo["n_steps"] * cfg.taxis // cfg.minibatches)
    model = MaskablePPO("MlpPolicy", vec, verbose=0, device="cpu", batch_size=batch_size, **cfg.ppo)
    model.action_space.seed(cfg.seed)
    curve = _Curve(cfg, log)
    start = time.perf_counter()
    with curve.bar:
        model.learn(total_timesteps=cfg.timesteps, callback=curve)
    curve.record()
    seconds = time.perf_counter() - start
    vec.close()
    final = play(cfg, model_policy(model))
    greedy, stay = play(cfg, greedy_policy), play(cfg, stay_policy)
    doc = {
        "format": "surge.rl-training/1",
        "command": command,
        "date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
        "machine": machine(),
        "library": {"stable_baselines3": _version("stable_baselines3"), "sb3_contrib": _version("sb3_contrib"), "supersuit": _version("supersuit"),
                    "pettingzoo": _version("pettingzoo"), "torch": torch.__version__},
        "config": asdict(cfg),
        "train_seconds": round(seconds, 1),
        "curve": curve.points,
        "episodes": {"ppo": final, "greedy": greedy, "stay": stay},
        "mean_total_cost": {k: float(np.mean([r["total_cost"] for r in v])) for k, v in
                            (("ppo", final), ("greedy", greedy), ("stay", stay))},
        "ppo_vs_greedy": paired_summary(final, greedy),
        "ppo_vs_stay": paired_summary(final, stay),
    }
    return model, doc


def _version(module: str) -> str:
    from importlib.metadata import version

    return version(module.replace("_", "-"))


def plot(doc: dict, path: Path) -> None:
    """The learning curve: mean evaluation cost against agent-steps, with greedy and stay as lines."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.4, 4), layout="tight")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    xs = [p["timesteps"] for p in doc["curve"]]
    ax.plot(xs, [p["mean_total_cost"] for p in doc["curve"]], marker="o", label="maskable PPO, shared policy")
    for name, style in (("greedy", "--"), ("stay", ":")):
        ax.axhline(doc["mean_total_cost"][name], linestyle=style, color="k" if name == "greedy" else "0.5", label=name)
    cfg = doc["config"]
    ax.set_xlabel("agent-steps trained (one taxi-minute each)")
    ax.set_ylabel("mean total cost (request-minutes waited)")
    ax.set_title(f"{cfg['scenario']}, {cfg['taxis']} taxis, {cfg['hour']}:00 +{cfg['minutes']} min; "
                 f"eval {', '.join(cfg['eval_dates'])} x {len(cfg['eval_seeds'])} seeds", fontsize=9)
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=100)


def write(doc: dict, out: Path) -> tuple[Path, Path]:
    """``rl-training.json`` and ``rl-training.png`` in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    json_path, png_path = out / "rl-training.json", out / "rl-training.png"
    json_path.write_text(json.dumps(doc, indent=1) + "\n")
    plot(doc, png_path)
    return json_path, png_path

