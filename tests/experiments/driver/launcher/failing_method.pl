/*  An aggregation method whose step fails at run time (tests of loud failures). */
:- multifile dfrl_aggregation:aggregate_init/3, dfrl_aggregation:aggregate_step/4,
             dfrl_aggregation:aggregate_final/3.

dfrl_aggregation:aggregate_init(failing, qtable(_, V), V).
dfrl_aggregation:aggregate_step(failing, _, _, _) :- fail.
dfrl_aggregation:aggregate_final(failing, A, A).
