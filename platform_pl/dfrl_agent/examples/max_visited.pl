% An aggregation method injected at runtime: `max_visited`, the element-wise
% maximum over the robots that have visited the entry (their visit count for
% that state-action pair is above 0); entries nobody visited get the plain mean.
%
% Why: with zero-initialised tables the paper's `max` keeps the 0 of every
% robot that never tried an action over the negative (danger) value learnt by
% the robot that did, so danger is forgotten and the table's sum ratchets up.
% Ignoring unvisited entries keeps what the robots actually learnt.
%
% Load it into every node of a running experiment and switch to it with
% `dfrl inject RESULTS --program THIS_FILE --method max_visited`.
:- multifile dfrl_aggregation:aggregate_init/3,
             dfrl_aggregation:aggregate_step/4,
             dfrl_aggregation:aggregate_final/3,
             dfrl_aggregation:method_uses_visits/1.

dfrl_aggregation:method_uses_visits(max_visited).

% Accumulator: mv(Best, Seen, Sum, N): Best the largest value among visitors so
% far (0.0 where none), Seen 1 where some robot visited, Sum the plain sum of
% all values and N the number of tables (for the unvisited entries' mean).
dfrl_aggregation:aggregate_init(max_visited, qtable_visits(_, Q, W), mv(B, S, Q, 1)) :-
    maplist(mv_first, Q, W, B, S).
dfrl_aggregation:aggregate_step(max_visited, mv(B0, S0, Sum0, N0), qtable_visits(_, Q, W),
                          mv(B, S, Sum, N)) :-
    mv_next(B0, S0, Q, W, B, S),
    maplist([X, Y, Z]>>(Z is X + Y), Sum0, Q, Sum),
    N is N0 + 1.
dfrl_aggregation:aggregate_final(max_visited, mv(B, S, Sum, N), Values) :-
    maplist([Bi, Si, Xi, V]>>( Si =:= 1 -> V = Bi ; V is Xi / N ), B, S, Sum, Values).

mv_first(Q, W, B, S) :-
    (   W > 0 -> B = Q, S = 1 ; B = 0.0, S = 0 ).

mv_next([], [], [], [], [], []).
mv_next([B0|B0s], [S0|S0s], [Q|Qs], [W|Ws], [B|Bs], [S|Ss]) :-
    (   W > 0
    ->  ( S0 =:= 1 -> B is max(B0, Q) ; B = Q ),
        S = 1
    ;   B = B0, S = S0
    ),
    mv_next(B0s, S0s, Qs, Ws, Bs, Ss).
