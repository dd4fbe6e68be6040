"""Reinforcement-learning environments: the time trial as a Gymnasium environment.

:class:`~racing_lib.envs.time_trial.TimeTrialEnv` puts any plant (the simulated car, a CommonRoad
car, a plant of your own) on any circuit (a built-in track, a racetrack-database file, or a
circuit drawn afresh per episode) behind Gymnasium's ``Env`` API, and
:class:`~racing_lib.envs.time_trial.MPCPolicy` drives it with the course's planner and coupled
MPC, the baseline a learned policy is compared with. Gymnasium is an optional extra:
``pip install "racing-lib[gym]"``.

Importing this package registers the environment as ``racing_lib/TimeTrial-v0``;
``gymnasium.make("racing_lib.envs:racing_lib/TimeTrial-v0", ...)`` imports it on the way, and
the package declares the ``gymnasium.envs`` entry point for Gymnasium versions that load plugins.
"""

from __future__ import annotations

from racing_lib.errors import PlantError

__all__ = ["ENV_ID", "register_envs"]

#: The environment's id in Gymnasium's registry.
ENV_ID = "racing_lib/TimeTrial-v0"


def register_envs() -> None:
    """Register ``racing_lib/TimeTrial-v0`` with Gymnasium (once; the entry point's target).

    Raises
    ------
    PlantError
        Gymnasium is not installed (the message gives the pip command).
    """
    try:
        # From the registration module, not the package: Gymnasium versions with a plugin loader
        # call this function while the package itself is still being imported.
        from gymnasium.envs.registration import register, registry
    except ImportError:
        raise PlantError(
            "the Gymnasium environment needs the gymnasium package: "
            'pip install "racing-lib[gym]" (or pip install "gymnasium>=1.0").'
        ) from None
    if ENV_ID not in registry:
        register(id=ENV_ID, entry_point="racing_lib.envs.time_trial:TimeTrialEnv")


register_envs()
