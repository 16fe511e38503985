import pytest
import torch
from tensordict import TensorDict
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.objectives import SoftUpdate

from torchrl_cebp.agents import (
    HERDDPGLoss,
    HERExploration,
    ObsGoalNormalizer,
    RunningNormalizer,
    make_actor,
    make_critic,
)

GAMMA = 0.98


def _batch(n: int, reward: float = -1.0) -> TensorDict:
    def part():
        return {"agent_input": torch.randn(n, 28)}

    flags = torch.zeros(n, 1, dtype=torch.bool)
    return TensorDict(
        {
            **part(),
            "action": torch.rand(n, 4) * 2 - 1,
            "next": {**part(), "reward": torch.full((n, 1), reward), "done": flags, "terminated": flags.clone()},
        },
        [n],
    )


def _loss(critic_bias: float | None = None) -> HERDDPGLoss:
    torch.manual_seed(0)
    critic = make_critic(28, 4)
    if critic_bias is not None:
        with torch.no_grad():
            critic.module[-1].bias.fill_(critic_bias)
    loss = HERDDPGLoss(make_actor(28, 4), critic, gamma=GAMMA)
    SoftUpdate(loss, tau=0.05)
    return loss


def _critic_grads(loss: HERDDPGLoss, batch: TensorDict) -> list[torch.Tensor]:
    loss.zero_grad()
    loss(batch)["loss_value"].backward()
    return [p.grad.clone() for p in loss.value_network_params.values(True, True)]


class TestRunningNormalizer:
    def test_matches_batch_statistics_whatever_the_chunks(self):
        x = torch.randn(1000, 3) * torch.tensor([1.0, 10.0, 0.0]) + 4
        norm = RunningNormalizer(3)
        for chunk in x.split(77):
            norm.update(chunk)
        torch.testing.assert_close(norm.mean, x.mean(0))
        expected_std = x.std(0, unbiased=False).clamp_min(0.01)
        torch.testing.assert_close(norm.std, expected_std, rtol=1e-4, atol=1e-5)

    def test_clips_and_round_trips_state(self):
        norm = RunningNormalizer(2, clip=5.0)
        norm.update(torch.tensor([[0.0, 0.0], [0.0, 0.0]]))
        # constant data: std floored at eps = 0.01, so 1.0 -> 100 -> clipped to 5
        assert norm(torch.tensor([1.0, -1.0])).tolist() == [5.0, -5.0]
        other = RunningNormalizer(2)
        other.load_state_dict(norm.state_dict())
        assert other.std.tolist() == norm.std.tolist()

    def test_obs_goal_normalizer_clips_raw_values_first(self):
        norm = ObsGoalNormalizer(obs_dim=1, goal_dim=1)
        td = TensorDict({"observation": torch.tensor([[1e6], [-1e6]]), "desired_goal": torch.zeros(2, 1)}, [2])
        norm.update(td)
        assert norm.obs.sumsq.item() == pytest.approx(2 * 200.0**2)
        assert norm(td)["agent_input"].shape == (2, 2)


class TestHERDDPGLoss:
    def test_critic_target_clipped_above_at_zero(self):
        out = _loss()(_batch(16, reward=5.0))
        assert (out["target_value"] <= 0).all()
        assert (out["target_value"] == 0).any()

    def test_critic_target_clipped_below(self):
        out = _loss(critic_bias=-1e4)(_batch(16, reward=-1.0))
        assert torch.allclose(out["target_value"], torch.full((16,), -1 / (1 - GAMMA)))

    def test_zero_is_weight_removes_a_sample_from_the_critic_gradient(self):
        loss = _loss()
        batch = _batch(8)
        batch["priority_weight"] = torch.tensor([0.0] + [1.0] * 7)
        reference = _critic_grads(loss, batch.clone())
        perturbed = batch.clone()
        perturbed[0] = _batch(1)[0]
        perturbed["next", "reward"][0] = 1e3
        for g, h in zip(reference, _critic_grads(loss, perturbed), strict=True):
            torch.testing.assert_close(g, h)
        # and it is baselines' mean(w * delta^2) over all 8: 7/8 of the other samples' unweighted mean
        for g, h in zip(reference, _critic_grads(loss, batch[1:].exclude("priority_weight")), strict=True):
            torch.testing.assert_close(g, h * 7 / 8)

    def test_the_weighted_critic_loss_is_baselines_mean_of_weight_times_squared_error(self):
        batch = _batch(8)
        batch["priority_weight"] = torch.linspace(0.01, 1.0, 8)
        out = _loss()(batch)
        expected = (batch["priority_weight"] * (out["pred_value"] - out["target_value"]).square()).mean()
        torch.testing.assert_close(out["loss_value"], expected)

    def test_is_weights_change_the_critic_loss(self):
        loss = _loss()
        batch = _batch(8)
        unweighted = loss(batch.clone())["loss_value"]
        batch["priority_weight"] = torch.linspace(0.1, 1.0, 8)
        assert not torch.isclose(loss(batch)["loss_value"], unweighted)

    def test_actor_loss_has_the_action_penalty(self):
        loss = _loss()
        batch = _batch(8)
        out = loss(batch.clone())
        td = loss.actor_network(batch.select("agent_input").clone())
        q = loss.value_network(td)["state_action_value"]
        expected = -q.mean() + td["action"].square().mean()
        torch.testing.assert_close(out["loss_actor"], expected)
        assert out["action_l2"] == pytest.approx(td["action"].square().mean().item())

    def test_writes_the_absolute_td_error_for_prioritised_samplers(self):
        # baselines' PER priority is |TD error| + eps; TorchRL's DDPGLoss writes the square
        batch = _batch(8)
        out = _loss()(batch)
        assert batch["td_error"].shape == (8,)
        torch.testing.assert_close(batch["td_error"], (out["pred_value"] - out["target_value"]).abs())
        torch.testing.assert_close(out["td_error"], batch["td_error"])


class TestHERExploration:
    def test_random_fraction_and_bounds(self):
        torch.manual_seed(0)
        td = TensorDict({"action": torch.full((20000, 4), 0.5)}, [20000])
        action = HERExploration(random_eps=0.3, noise_std=0.2)(td)["action"]
        assert action.abs().max() <= 1
        # Some dim below -0.3: 4 noise sigmas away for a noised action, probability
        # 1 - 0.65^4 = 0.82 for a uniform one, so about 0.3 * 0.82 of the rows.
        below = (action < -0.3).any(-1).float().mean().item()
        assert below == pytest.approx(0.3 * (1 - 0.65**4), abs=0.02)

    def test_deterministic_mode_passes_the_policy_through(self):
        td = TensorDict({"action": torch.full((10, 4), 0.5)}, [10])
        with set_exploration_type(ExplorationType.DETERMINISTIC):
            assert (HERExploration()(td)["action"] == 0.5).all()

    def test_own_generator_repeats_and_leaves_the_global_stream_alone(self):
        def noisy(seed: int) -> torch.Tensor:
            td = TensorDict({"action": torch.zeros(50, 4)}, [50])
            return HERExploration(generator=torch.Generator().manual_seed(seed))(td)["action"]

        torch.manual_seed(0)
        before = torch.get_rng_state()
        assert torch.equal(noisy(3), noisy(3)) and not torch.equal(noisy(3), noisy(4))
        assert torch.equal(torch.get_rng_state(), before)
