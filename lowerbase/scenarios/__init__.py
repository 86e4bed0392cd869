"""Scenarios: a timeline and expectations, loaded from TOML (the library in library/) and run
on the simulated loop or over real processes; kinds: wheeled, world, tasks, trace, legged."""
