"""``dqn``: a small MLP Q-network with experience replay and a target network.

The network maps the observation (8 IR proximities) through ``hidden`` fully connected ReLU
layers to one value per action (default 8 -> 64 -> 64 -> 3, 4,931 parameters, float64). Every
environment step the transition goes into a replay buffer (:class:`ReplayBuffer`); once it
holds ``learning_starts`` transitions, every ``train_every`` steps a minibatch of
``batch_size`` transitions drawn uniformly (with replacement) is fitted to the targets of the
target network

    y = r + gamma * max_a' Q_target(x', a')      (y = r when terminal)    (dqn_targets)

by one Adam step on the mean Huber loss of ``Q(x, a) - y`` (:func:`huber`). The gradient comes
from autograd (``autograd.grad``, reverse mode over numpy); nothing here differentiates by
hand. The target network is a copy of the online network, refreshed every
``target_update`` gradient steps. Exploration is the shared epsilon-greedy schedule, clocked
by environment steps.

The library: autograd (HIPS), chosen by measurement over JAX and PyTorch (robots/README.md,
"Function-approximation learners"): well under a MB installed beside numpy, ~0.2 s to import,
about 1 ms per minibatch update here, all of it numpy, so the same seed gives the same bits.

Parameters for the federated layer (:attr:`DQN.param_layout`): ``w1 (8, 64), b1 (64,),
w2 (64, 64), b2 (64,), w3 (64, A), b3 (A,)``; ``set_params`` sets the online and the target
network and keeps the Adam moments and the replay buffer.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from dfrl.robots.approx import FunctionLearner, Layout, QModel, flatten, unflatten, validate_params

if TYPE_CHECKING:
    from dfrl.robots.td import LearnerParams


@dataclass(frozen=True)
class DQNConfig:
    """Hyper-parameters of :class:`DQN` (``gamma`` and ``epsilon`` come from ``LearnerParams``).

    Attributes
    ----------
    hidden : tuple of int
        Widths of the hidden ReLU layers.
    lr : float
        Adam step size.
    batch_size : int
        Transitions per gradient step.
    buffer_size : int
        Replay capacity (oldest transitions are overwritten).
    learning_starts : int
        Transitions collected before the first gradient step.
    train_every : int
        Environment steps between gradient steps.
    target_update : int
        Gradient steps between copies of the online network into the target network.
    huber_delta : float
        Where the Huber loss turns from quadratic to linear.
    """

    hidden: tuple[int, ...] = (64, 64)
    lr: float = 1e-3
    batch_size: int = 64
    buffer_size: int = 20_000
    learning_starts: int = 500
    train_every: int = 1
    target_update: int = 250
    huber_delta: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "hidden", tuple(int(h) for h in self.hidden))
        if any(h < 1 for h in self.hidden):
            raise ValueError(f"hidden widths must be positive, got {self.hidden}")
        if not self.lr > 0.0:
            raise ValueError(f"lr must be positive, got {self.lr}")
        for name in ("batch_size", "buffer_size", "train_every", "target_update"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.learning_starts < 0:
            raise ValueError("learning_starts must be >= 0")
        if not self.huber_delta > 0.0:
            raise ValueError("huber_delta must be positive")


# -- pure maths ----------------------------------------------------------------------------
def dqn_targets(
    rewards: np.ndarray, next_q: np.ndarray, terminals: np.ndarray, gamma: float
) -> np.ndarray:
    """Q-learning targets of a minibatch: ``r + gamma * max_a' next_q`` (``r`` if terminal).

    Parameters
    ----------
    rewards : np.ndarray, shape (B,)
    next_q : np.ndarray, shape (B, n_actions)
        The target network's values of the next observations.
    terminals : np.ndarray of bool, shape (B,)
    gamma : float
    """
    boot = np.where(terminals, 0.0, next_q.max(axis=1))
    return np.asarray(rewards, dtype=np.float64) + gamma * boot


def mlp_layout(obs_dim: int, hidden: tuple[int, ...], n_actions: int) -> Layout:
    """Names and shapes of the network's weights and biases, input layer first."""
    sizes = (obs_dim, *hidden, n_actions)
    layout: Layout = []
    for k, (a, b) in enumerate(zip(sizes[:-1], sizes[1:]), start=1):
        layout += [(f"w{k}", (a, b)), (f"b{k}", (b,))]
    return layout


def mlp_forward(weights: list[Any], x: Any, xp: Any = np) -> Any:
    """Action values of a batch: ReLU hidden layers, linear output.

    Parameters
    ----------
    weights : list of arrays
        ``[w1, b1, w2, b2, ...]`` as :func:`mlp_layout`.
    x : array, shape (B, obs_dim)
    xp : module
        ``numpy`` or ``autograd.numpy`` (for differentiation).

    Returns
    -------
    array, shape (B, n_actions)
    """
    h = x
    n_layers = len(weights) // 2
    for k in range(n_layers):
        h = h @ weights[2 * k] + weights[2 * k + 1]
        if k < n_layers - 1:
            h = xp.maximum(h, 0.0)
    return h


def huber(d: Any, delta: float, xp: Any = np) -> Any:
    """Elementwise Huber loss: ``d**2 / 2`` for ``|d| <= delta``, else
    ``delta * (|d| - delta/2)``."""
    a = xp.abs(d)
    return xp.where(a <= delta, 0.5 * d * d, delta * (a - 0.5 * delta))


def init_mlp(layout: Layout, rng: np.random.Generator) -> list[np.ndarray]:
    """He-uniform weights (bound ``sqrt(6 / fan_in)``), zero biases."""
    out = []
    for name, shape in layout:
        if name.startswith("w"):
            bound = np.sqrt(6.0 / shape[0])
            out.append(rng.uniform(-bound, bound, size=shape))
        else:
            out.append(np.zeros(shape, dtype=np.float64))
    return out


@dataclass
class Adam:
    """Adam's moments and step count for a list of arrays (Kingma & Ba, default betas).

    Only the optimiser's bookkeeping; the gradients it is given come from autograd.
    """

    lr: float
    m: list[np.ndarray]
    v: list[np.ndarray]
    step_count: int = 0
    beta1: float = 0.9
    beta2: float = 0.999
    eps: float = 1e-8

    @classmethod
    def for_arrays(cls, arrays: list[np.ndarray], lr: float) -> "Adam":
        return cls(
            lr=lr, m=[np.zeros_like(a) for a in arrays], v=[np.zeros_like(a) for a in arrays]
        )

    def step(self, arrays: list[np.ndarray], grads: list[np.ndarray]) -> None:
        """Update ``arrays`` in place from their gradients."""
        self.step_count += 1
        c1 = 1.0 - self.beta1**self.step_count
        c2 = 1.0 - self.beta2**self.step_count
        for a, g, m, v in zip(arrays, grads, self.m, self.v):
            m *= self.beta1
            m += (1.0 - self.beta1) * g
            v *= self.beta2
            v += (1.0 - self.beta2) * g * g
            a -= self.lr * (m / c1) / (np.sqrt(v / c2) + self.eps)


class ReplayBuffer:
    """A ring buffer of transitions ``(x, a, r, x', terminal)``, sampled uniformly.

    Parameters
    ----------
    capacity : int
    obs_dim : int
    """

    def __init__(self, capacity: int, obs_dim: int) -> None:
        if capacity < 1:
            raise ValueError("capacity must be >= 1")
        self.capacity = capacity
        self.obs = np.zeros((capacity, obs_dim), dtype=np.float64)
        self.next_obs = np.zeros((capacity, obs_dim), dtype=np.float64)
        self.actions = np.zeros(capacity, dtype=np.int64)
        self.rewards = np.zeros(capacity, dtype=np.float64)
        self.terminals = np.zeros(capacity, dtype=np.bool_)
        self.size = 0  #: transitions held, at most ``capacity``
        self.added = 0  #: transitions ever added; the next goes to ``added % capacity``

    def __len__(self) -> int:
        return self.size

    def add(
        self, obs: np.ndarray, action: int, reward: float, next_obs: np.ndarray, terminal: bool
    ) -> None:
        """Store a transition, overwriting the oldest when full."""
        i = self.added % self.capacity
        self.obs[i], self.actions[i], self.rewards[i] = obs, action, reward
        self.next_obs[i], self.terminals[i] = next_obs, terminal
        self.added += 1
        self.size = min(self.size + 1, self.capacity)

    def sample(self, batch_size: int, rng: np.random.Generator) -> tuple[np.ndarray, ...]:
        """``batch_size`` transitions drawn uniformly with replacement from those held.

        Returns
        -------
        obs (B, obs_dim), actions (B,), rewards (B,), next_obs (B, obs_dim), terminals (B,)
            Copies.

        Raises
        ------
        ValueError
            The buffer is empty.
        """
        if self.size == 0:
            raise ValueError("cannot sample from an empty replay buffer")
        idx = rng.integers(0, self.size, size=batch_size)
        return (
            self.obs[idx],
            self.actions[idx],
            self.rewards[idx],
            self.next_obs[idx],
            self.terminals[idx],
        )


def _loss_gradient(huber_delta: float) -> Callable[..., list[np.ndarray]]:
    """``grad(loss)(weights, x, actions, targets)`` for the mean Huber loss, by autograd."""
    import autograd.numpy as anp
    from autograd import grad

    def loss(weights: list[Any], x: np.ndarray, actions: np.ndarray, targets: np.ndarray) -> Any:
        q = mlp_forward(weights, x, anp)
        q_taken = q[np.arange(x.shape[0]), actions]
        return anp.mean(huber(q_taken - targets, huber_delta, anp))

    return grad(loss)


class DQN(FunctionLearner):
    """Deep Q-learning (replay, target network) with a small MLP; see the module doc.

    Parameters
    ----------
    obs_dim, n_actions : int
    params : LearnerParams
        ``gamma`` and ``epsilon`` (``alpha`` and ``initial_q`` are unused: see ``config.lr``).
    rng : np.random.Generator
        Initial weights, exploration and minibatch draws.
    config : DQNConfig, optional
        ``TrainerConfig.dqn``.

    Attributes
    ----------
    online, target : list of np.ndarray
        The networks' arrays in :attr:`param_layout` order.
    buffer : ReplayBuffer
    updates : int
        Gradient steps done.
    """

    name = "dqn"
    config_field = "dqn"

    def __init__(
        self,
        obs_dim: int,
        n_actions: int,
        params: "LearnerParams",
        rng: np.random.Generator,
        config: DQNConfig | None = None,
    ) -> None:
        super().__init__(obs_dim, n_actions, params, rng)
        self.config = config or DQNConfig()
        self._layout = mlp_layout(obs_dim, self.config.hidden, n_actions)
        self.online = init_mlp(self._layout, rng)
        self.target = [a.copy() for a in self.online]
        self.optimizer = Adam.for_arrays(self.online, self.config.lr)
        self.buffer = ReplayBuffer(self.config.buffer_size, obs_dim)
        self.updates = 0
        self._grad = _loss_gradient(self.config.huber_delta)

    def q_values(self, obs: np.ndarray) -> np.ndarray:
        x = np.asarray(obs, dtype=np.float64).reshape(1, -1)
        return mlp_forward(self.online, x)[0]

    def learn(
        self, obs: np.ndarray, action: int, reward: float, next_obs: np.ndarray, terminal: bool
    ) -> int:
        self._observed(obs, action)
        self.buffer.add(obs, action, reward, next_obs, terminal)
        self.t += 1
        c = self.config
        if len(self.buffer) >= max(c.learning_starts, 1) and self.t % c.train_every == 0:
            self.train_step()
        return self.select_action(next_obs)

    def train_step(self) -> None:
        """One Adam step on a replayed minibatch; sync the target network when it is due."""
        x, a, r, x2, term = self.buffer.sample(self.config.batch_size, self.rng)
        y = dqn_targets(r, mlp_forward(self.target, x2), term, self.params.gamma)
        grads = self._grad(self.online, x, a, y)
        self.optimizer.step(self.online, grads)
        self.updates += 1
        if self.updates % self.config.target_update == 0:
            self.sync_target()

    def sync_target(self) -> None:
        """Copy the online network into the target network."""
        for t, o in zip(self.target, self.online):
            t[...] = o

    def q_model(self) -> tuple[list[np.ndarray], QModel]:
        """The online network's arrays and :func:`mlp_forward`."""
        return self.online, mlp_forward

    def after_distil(self) -> None:
        """A distilled network is also the target (as after :meth:`set_params`)."""
        self.sync_target()

    @property
    def param_layout(self) -> Layout:
        return list(self._layout)

    def get_params(self) -> np.ndarray:
        return flatten(self.online)

    def set_params(self, vec: np.ndarray) -> None:
        arrays = unflatten(validate_params(vec, self._layout), self._layout)
        for o, t, new in zip(self.online, self.target, arrays):
            o[...] = new
            t[...] = new
