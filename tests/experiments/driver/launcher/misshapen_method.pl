/*  An aggregation method whose final aggregate is no table: the values
    wrapped in a term (tests of a finished aggregate's shape check). */
:- multifile dfrl_aggregation:aggregate_init/3, dfrl_aggregation:aggregate_step/4,
             dfrl_aggregation:aggregate_final/3.

dfrl_aggregation:aggregate_init(misshapen, qtable(_, V), V).
dfrl_aggregation:aggregate_step(misshapen, A, _, A).
dfrl_aggregation:aggregate_final(misshapen, A, wrapped(A)).
