/*  The average, taking half a second per robot: an agent that uses it stays on each stop
    long enough for a test to kill the stop's process while the agent is there.  */
:- multifile dfrl_aggregation:aggregate_init/3, dfrl_aggregation:aggregate_step/4,
             dfrl_aggregation:aggregate_final/3.

dfrl_aggregation:aggregate_init(slow, Table, Acc) :-
    dfrl_aggregation:aggregate_init(average, Table, Acc).
dfrl_aggregation:aggregate_step(slow, Acc0, Table, Acc) :-
    sleep(0.5),
    dfrl_aggregation:aggregate_step(average, Acc0, Table, Acc).
dfrl_aggregation:aggregate_final(slow, Acc, Table) :-
    dfrl_aggregation:aggregate_final(average, Acc, Table).
