% An aggregation method injected at runtime: element-wise median of the
% robots' tables. Load it into every node of a running experiment with
% `dfrl inject RESULTS --program THIS_FILE --method median`.
:- multifile dfrl_aggregation:aggregate_init/3,
             dfrl_aggregation:aggregate_step/4,
             dfrl_aggregation:aggregate_final/3.

% The accumulator is the list of tables seen so far (as value lists).
dfrl_aggregation:aggregate_init(median, qtable(_, V), [V]).
dfrl_aggregation:aggregate_step(median, Vs, qtable(_, V), [V|Vs]).
dfrl_aggregation:aggregate_final(median, Vs, Median) :-
    transpose_rows(Vs, Columns),
    maplist(median_of, Columns, Median).

transpose_rows([[]|_], []) :- !.
transpose_rows(Rows, [Col|Cols]) :-
    maplist([[H|T], H, T]>>true, Rows, Col, Rests),
    transpose_rows(Rests, Cols).

median_of(Xs, M) :-
    msort(Xs, S),
    length(S, N),
    (   N mod 2 =:= 1
    ->  I is N // 2, nth0(I, S, M)
    ;   I is N // 2 - 1, J is I + 1, nth0(I, S, A), nth0(J, S, B), M is (A + B) / 2
    ).
