"""People who walk like people: a pedestrian-dynamics core for the simulator (docs/people.md).

social_force.py  the model: what accelerates each person (pure, numba), and a plain integrator
plans.py         routes, waits, groups and flows of arriving people; the fixed-size population
spec.py          the world file's `people:` key
fundamental.py   the model against Weidmann's speed-density relation
"""
