:- module(bridge_bench,
          [ bench_table_round_trips/4,  % +Robot, +Warmup, +Count, +Options
            bench_result/1              % -Result
          ]).
:- use_module(robot_bridge, [get_qtable/3, set_qtable/3]).
:- autoload(library(error), [must_be/2]).

/** <module> Agent side of `dfrl bench bridge`

An agent-like thread times get_qtable/3 followed by set_qtable/3 (of the
table it just read) while the host's control loop serves it.
*/

:- dynamic result_/1.

%!  bench_table_round_trips(+Robot, +Warmup, +Count, +Options) is det.
%
%   Run Warmup untimed, then Count timed read+write pairs on Robot, and
%   record bench(Total, Get, Set), three lists of milliseconds, for
%   bench_result/1. Options are passed to get_qtable/3 and set_qtable/3.
%   An exception is recorded as error(E).

bench_table_round_trips(Robot, Warmup, Count, Options) :-
    must_be(nonneg, Warmup),
    must_be(nonneg, Count),
    retractall(result_(_)),
    catch(( forall(between(1, Warmup, _), pair(Robot, Options, _, _)),
            findall(T-G-S, ( between(1, Count, _),
                             pair(Robot, Options, G, S),
                             T is G + S ), Triples),
            pairs(Triples, Ts, Gs, Ss),
            Result = bench(Ts, Gs, Ss)
          ),
          E, Result = error(E)),
    assertz(result_(Result)).

pair(Robot, Options, GetMs, SetMs) :-
    get_time(T0),
    get_qtable(Robot, Table, Options),
    get_time(T1),
    set_qtable(Robot, Table, Options),
    get_time(T2),
    GetMs is (T1 - T0) * 1000,
    SetMs is (T2 - T1) * 1000.

pairs([], [], [], []).
pairs([T-G-S|R], [T|Ts], [G|Gs], [S|Ss]) :-
    pairs(R, Ts, Gs, Ss).

%!  bench_result(-Result) is semidet.
%
%   Result of the finished run (and forget it); fails while it runs.

bench_result(Result) :-
    retract(result_(Result)).
