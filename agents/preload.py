"""What every agent process loads, loaded once by the parent that forks them; importing this module is the preloading.

The agents' fork server (:func:`coordinator.fleet.agent_context`) imports
it before it forks any agent: the agent's modules, and the serial compiled
kernels, loaded from numba's cache by planning a made-up minute in the
calling thread.  Forked agents share those pages copy-on-write instead of
each building its own copy.  Two things are left to each agent:

- the parallel kernel, whose GNU OpenMP runtime aborts a process that forks
  after starting it (``agents.rollout.warm_up(serial=True)`` does not load it);
- its zenoh session: the fork server never opens one, so no session, runtime
  thread or socket crosses a fork.
"""

from __future__ import annotations

import agents.taxi  # noqa: F401 - imported for its side effect: the agent's imports, once
from agents.rollout import warm_up
from city.scenario import load_city

# Any city types the kernels alike; a mapped one leaves no matrices in the heap the agents inherit.
warm_up(load_city("synthetic", mmap=True), serial=True)
