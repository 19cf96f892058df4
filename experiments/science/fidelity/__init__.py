"""``dfrl bench sim-fidelity``: is the batched simulator a stand-in for pybullet? Four checks.

1. **Sensing** (:mod:`.sensing`): the IR readings of both simulators at the same poses.
2. **Transitions** (:mod:`.sensing`): from the poses and wheel states of a pybullet random
   walk, the same action in both; the share of next discretised states that agree and the
   visit-weighted total variation distance of the next-state distributions per (state, action),
   beside the same distance between two batched replays (its floor: sampling and motion noise).
3. **Fixed policies** (:mod:`.policies`): collisions per 1,000 steps and progress of three
   fixed policies in both, with Welch intervals of the differences.
4. **Learning, the decisive one** (:mod:`.learning`): tables learnt in each simulator, all
   evaluated in pybullet; per seed the mean score of its block of batched-learnt tables minus
   that of its pybullet-learnt block; the 95% interval over seeds must lie within the margin.

:mod:`.report` runs them and writes the report; robots/README.md ("The batched simulator")
quotes its numbers.
"""
