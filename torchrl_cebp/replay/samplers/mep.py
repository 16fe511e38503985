"""Maximum Entropy-regularized multi-goal Prioritization (MEP, Zhao et al. 2019)."""
from __future__ import annotations

from typing import Any

import numpy as np
import torch
from sklearn.mixture import BayesianGaussianMixture
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torchrl.data.replay_buffers.storages import Storage

from torchrl_cebp.replay.episodes import episode_lengths, stored_lengths, valid_steps
from torchrl_cebp.replay.samplers.base import EpisodePrioritySampler, checked, episode_positions, require_same_sampler

# The paper's code adds it to the dense rank (from 0), so that the most common trajectories stay drawable.
RANK_OFFSET = 0.001
# Scores within this share of their raw magnitude tie in the dense rank. A trajectory's -log density differs in
# its last bits with the batch that scored it (BLAS kernels sum in a batch-dependent order; seen: 5.8e-11 on 2.6e5,
# 2e-16 relative, on an AVX-512 CPU), so an exact rank would give one trajectory two ranks, by which write brought it.
# 1e-9 leaves seven orders of magnitude above that noise, and is far below any density difference worth a rank.
SCORE_RTOL = 1e-9
# What score_samples reads of a fitted BayesianGaussianMixture (sklearn's public fitted state), saved by name.
MIXTURE_STATE = ("weight_concentration_", "mean_precision_", "means_", "degrees_of_freedom_",
                 "covariances_", "precisions_cholesky_")


def dense_ranks(scores: np.ndarray, rtol: float = 0.0, shift: float = 0.0) -> np.ndarray:
    """Dense ranks from 0 of ``scores``; a score within ``rtol`` of the next lower one, relative to its raw value
    ``score + shift`` (at least 1), shares that one's rank.

    The ranks are a function of the set of scores alone, not of their order or of which write brought them.

    Args:
        scores (np.ndarray): ``[n]`` scores.
        rtol (float, optional): the relative gap between sorted neighbours that is still a tie. Defaults to ``0.0``.
        shift (float, optional): what was subtracted from the raw scores, whose magnitude sets their float noise.
            Defaults to ``0.0``.

    Example:
        >>> dense_ranks(np.array([3.0, 1.0, 1.0 + 1e-15, 2.0]), rtol=1e-12).tolist()
        [2, 0, 0, 1]
    """
    order = np.argsort(scores)  # equal scores share a rank, so their order among themselves does not matter
    ordered = scores[order]
    tolerance = rtol * np.maximum(np.abs(ordered[1:] + shift), 1.0)
    ranks = np.empty(len(scores), dtype=np.int64)
    ranks[order] = np.concatenate([[0], np.cumsum(np.diff(ordered) > tolerance)])
    return ranks


class MEPSampler(EpisodePrioritySampler):
    """Rare achieved-goal trajectories first: rank of the -log density under a Bayesian GMM.

    :meth:`refit` fits a :class:`sklearn.mixture.BayesianGaussianMixture` on the buffer's achieved-goal trajectories;
    every write ranks the whole buffer again (the formula is on the :doc:`samplers page </samplers>`). Until the
    first refit every rank is 0: uniform draws. No importance-sampling weights.

    Args:
        n_components (int, optional): mixture components. Defaults to ``3``, MEP's.
        temperature (float, optional): sets the rank exponent. Defaults to ``1.0``.
        max_fit_episodes (int, optional): fit on at most this many stored episodes, drawn at random (all are
            scored); bounds a refit's cost. Defaults to ``5000``.
        max_iter (int, optional): EM iterations per refit. Defaults to ``100``.
        reg_covar (float, optional): added to the covariances' diagonal and to the Wishart prior's, which an early
            buffer's many identical trajectories make singular; 1e-4 is a 1 cm standard deviation. Defaults to ``1e-4``.
        seed (int, optional): seeds the mixture's initialisation and the fit subsample. Defaults to ``0``.
        position_key (NestedKey, optional): the object's position before a step. Defaults to ``"achieved_goal"``.
        next_position_key (NestedKey, optional): its position after a step. Defaults to ``("next", "achieved_goal")``.
        end_key (NestedKey, optional): the flag that ends an episode before its row. Defaults to ``("next", "done")``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
        >>> from torchrl_cebp.replay.samplers import MEPSampler
        >>> rb = TensorDictReplayBuffer(storage=LazyTensorStorage(100 * 50, ndim=2), sampler=MEPSampler(),
        ...                             batch_size=4, dim_extend=0)
        >>> _ = rb.extend(TensorDict({"achieved_goal": torch.rand(20, 50, 3),
        ...                           "next": {"achieved_goal": torch.rand(20, 50, 3)}}, [20, 50]))
        >>> rb.sampler.refit(rb.storage)
        >>> rb.sample().shape
        torch.Size([4])
    """

    def __init__(
        self, n_components: int = 3, temperature: float = 1.0, *, max_fit_episodes: int = 5000, max_iter: int = 100,
        reg_covar: float = 1e-4, seed: int = 0, position_key: NestedKey = "achieved_goal",
        next_position_key: NestedKey = ("next", "achieved_goal"), end_key: NestedKey = ("next", "done"),
    ) -> None:
        super().__init__(end_key)
        self.n_components = int(checked("MEPSampler", "n_components", n_components, minimum=1))
        self.temperature = checked("MEPSampler", "temperature", temperature)
        self.max_fit_episodes = int(checked("MEPSampler", "max_fit_episodes", max_fit_episodes, minimum=1))
        self.max_iter = int(checked("MEPSampler", "max_iter", max_iter, minimum=1))
        self.reg_covar = checked("MEPSampler", "reg_covar", reg_covar, exclusive=True)
        self.seed = int(seed)
        self.position_key = position_key
        self.next_position_key = next_position_key
        self._mixture: BayesianGaussianMixture | None = None
        self._lowest_fit_score = 0.0
        self._scores = torch.zeros(0, dtype=torch.float64)  # per episode row; 0 until the first refit
        self._n_refits = 0
        self._levels = torch.zeros(0, dtype=torch.float64)  # the priority of each rank

    def episode_keys(self) -> dict[NestedKey, tuple[int | None, ...]]:
        """The entries read: the object's position before and after each step, ``(3,)`` each."""
        return {self.position_key: (3,), self.next_position_key: (3,)}

    def _new_mixture(self, covariance_prior: np.ndarray | None = None) -> BayesianGaussianMixture:
        return BayesianGaussianMixture(
            n_components=self.n_components, weight_concentration_prior_type="dirichlet_distribution",
            covariance_prior=covariance_prior, max_iter=self.max_iter, reg_covar=self.reg_covar,
            random_state=self.seed + self._n_refits,
        )

    def _trajectories(self, episodes: TensorDictBase, valid: torch.Tensor) -> np.ndarray:
        # A trajectory that ended early keeps its last position: the padding adds no density of its own.
        positions = episode_positions(episodes, self.position_key, self.next_position_key)
        state = torch.minimum(torch.arange(positions.shape[1]), valid.sum(1, keepdim=True))
        positions = positions.gather(1, state.unsqueeze(-1).expand_as(positions))
        return positions.flatten(1).numpy()

    def _raw_scores(self, trajectories: np.ndarray) -> torch.Tensor:
        return torch.from_numpy(-self._mixture.score_samples(trajectories))

    def episode_priority(self, episodes: TensorDictBase, valid: torch.Tensor) -> torch.Tensor:
        """Rank 0's priority for each episode, ``[n]``: every episode's until the first :meth:`refit`."""
        # Rank 0's, every episode's until the first refit; after it, write_priorities ranks the buffer again.
        return self._rank_priorities(torch.zeros(episodes.shape[0], dtype=torch.long))

    def write_priorities(self, rows: torch.Tensor, episodes: TensorDictBase,
                         lengths: torch.Tensor | None = None) -> None:
        """Scores the written ``episodes`` at ``rows``; once the mixture is fitted, scores their trajectories under it
        and ranks every stored episode again."""
        if lengths is None:
            lengths = episode_lengths(episodes, self.end_key)
        n_before = self.n_episodes
        super().write_priorities(rows, episodes, lengths)
        if self._scores.numel() != self._tree.size:
            self._scores = torch.zeros(self._tree.size, dtype=torch.float64)
        if self._mixture is None:  # every score is 0 until the first refit: only rows new to the buffer get rank 0
            frontier = torch.arange(n_before, self.n_episodes)
            self.set_priorities(frontier, self._rank_priorities(torch.zeros_like(frontier)))
            return
        raw = self._raw_scores(self._trajectories(episodes, valid_steps(lengths, episodes.shape[1])))
        self._scores[rows] = (raw - self._lowest_fit_score).clamp(min=0.0)
        self._rank_stored()

    def _rank_stored(self) -> None:
        """Dense ranks from 0 of every stored episode's score, as priorities; only those that changed are set."""
        n = self.n_episodes
        ranks = dense_ranks(self._scores[:n].numpy(), rtol=SCORE_RTOL, shift=self._lowest_fit_score)
        priority = self._rank_priorities(torch.from_numpy(ranks))
        changed = (priority != self._priorities[:n]).nonzero().squeeze(-1)
        self.set_priorities(changed, priority.index_select(0, changed))

    def _rank_priorities(self, ranks: torch.Tensor) -> torch.Tensor:
        # A table, so that a rank's priority does not depend on which rows are written with it.
        if self._levels.numel() != self._tree.size:
            levels = torch.arange(self._tree.size, dtype=torch.float64) + RANK_OFFSET
            self._levels = levels.pow(1.0 / (self.temperature + 0.01))
        return self._levels[ranks]

    def refit(self, storage: Storage) -> None:
        """Fits the mixture on the stored trajectories, then scores and ranks every stored episode."""
        if self.n_episodes < self.n_components:
            return
        rows = torch.arange(self.n_episodes)
        valid = valid_steps(stored_lengths(storage, rows, self.end_key), storage.shape[1])
        trajectories = self._trajectories(storage.get(rows), valid)
        fit_rows = np.random.default_rng(self.seed + self._n_refits).permutation(len(rows))
        fit_data = trajectories[fit_rows[: self.max_fit_episodes]]
        prior = np.cov(fit_data.T) + self.reg_covar * np.eye(fit_data.shape[1])
        self._mixture = self._new_mixture(prior).fit(fit_data)
        self._n_refits += 1
        raw = self._raw_scores(trajectories)
        self._lowest_fit_score = float(raw.min())
        self._scores[rows] = raw - self._lowest_fit_score
        self._rank_stored()

    def state_dict(self) -> dict[str, Any]:
        """The base state, each row's score, the refit count and the fitted mixture's parameters, as tensors and
        numbers that ``torch.load(weights_only=True)`` reads."""
        state = super().state_dict()
        state.update(scores=self._scores.clone(), lowest_fit_score=self._lowest_fit_score, n_refits=self._n_refits)
        if self._mixture is not None:
            for name in MIXTURE_STATE:
                state[f"mixture_{name}"] = torch.tensor(np.asarray(getattr(self._mixture, name)))  # a copy
        return state

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        """Restores a :meth:`state_dict`, the fitted mixture included.

        Raises:
            ValueError: a state of another sampler kind or other arguments, or one without per-episode scores, from
                an older MEPSampler.
        """
        require_same_sampler(self, state_dict)  # first: another sampler's state lacks the scores too
        if "scores" not in state_dict:
            raise ValueError("this MEP state is from a version of MEPSampler that did not rank the whole buffer on "
                             "every write; it holds no per-episode scores to rank: start the run again")
        super().load_state_dict(state_dict)
        self._scores = state_dict["scores"].clone()
        self._lowest_fit_score = float(state_dict["lowest_fit_score"])
        self._n_refits = int(state_dict["n_refits"])
        self._mixture = None
        if f"mixture_{MIXTURE_STATE[0]}" in state_dict:
            self._mixture = self._new_mixture()
            for name in MIXTURE_STATE:
                setattr(self._mixture, name, state_dict[f"mixture_{name}"].numpy().copy())
            self._mixture.n_features_in_ = self._mixture.means_.shape[1]

    def _empty(self) -> None:
        # An emptied buffer starts over: uniform draws until the next refit.
        super()._empty()
        self._scores = torch.zeros_like(self._scores)
        self._mixture = None
        self._lowest_fit_score = 0.0

    def __repr__(self) -> str:
        return (f"MEPSampler(n_components={self.n_components}, temperature={self.temperature}, "
                f"refits={self._n_refits}, n_episodes={self.n_episodes})")
