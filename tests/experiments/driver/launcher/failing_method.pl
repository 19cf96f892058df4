/*  An aggregation method whose step fails at run time (tests of loud failures). */
:- multifile dfrl_agent:aggregate_init/3, dfrl_agent:aggregate_step/4,
             dfrl_agent:aggregate_final/3.

dfrl_agent:aggregate_init(failing, qtable(_, V), V).
dfrl_agent:aggregate_step(failing, _, _, _) :- fail.
dfrl_agent:aggregate_final(failing, A, A).
