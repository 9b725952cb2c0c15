"""The public API: what a user imports from the packages themselves, and what that import costs."""

from __future__ import annotations

import subprocess
import sys

import pytest

import nbs_env
import policies


@pytest.mark.parametrize("package", [nbs_env, policies], ids=lambda p: p.__name__)
def test_every_exported_name_resolves(package):
    """Each name of ``__all__`` is importable from the package, and is the object its module defines."""
    for name in package.__all__:
        value = getattr(package, name)
        assert value is not None, name
        module = getattr(value, "__module__", None)
        if module is not None and isinstance(value, type):
            assert module.startswith(package.__name__), f"{name} comes from {module}"


def test_the_env_and_its_configuration_from_the_package():
    from nbs_env import NBSEnv, RobotConfig, ScannerConfig, env, make_config

    assert NBSEnv is env.NBSEnv
    config = make_config("fast", scene="l_room", max_scans=3)
    assert isinstance(config.robot, RobotConfig)
    assert isinstance(config.robot.scanner, ScannerConfig)
    assert config.robot.scanner.angular_step == 1.0


def test_policies_by_class_and_by_name():
    from policies import BlaerAllenPolicy, GreedyPolicy, LearnedPolicy, make_policy

    assert isinstance(make_policy("greedy"), GreedyPolicy)
    assert isinstance(make_policy("blaer_allen"), BlaerAllenPolicy)
    assert isinstance(make_policy("ppo:reference"), LearnedPolicy)


def test_an_unknown_name_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'NoSuchThing'"):
        nbs_env.NoSuchThing  # noqa: B018
    with pytest.raises(AttributeError, match="no attribute 'NoSuchPolicy'"):
        policies.NoSuchPolicy  # noqa: B018


def test_importing_the_packages_stays_cheap():
    """``import nbs_env`` registers the env ids without loading the env's stack, and ``import policies``
    loads neither torch nor the compared methods: those names load on first use."""
    code = (
        "import sys, gymnasium, nbs_env; "
        "assert 'nbs_env/NBS-v0' in gymnasium.registry; "
        "first = [m for m in ('nbs_env.env', 'nbs_env.storey', 'open3d', 'torch') if m in sys.modules]; "
        "import policies; "
        "then = [m for m in ('nbs_env.env', 'policies.learned', 'policies.baselines', 'torch') if m in sys.modules]; "
        "print(first, then)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[] []"
