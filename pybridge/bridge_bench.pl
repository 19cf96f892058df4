:- module(bridge_bench,
          [ bench_table_round_trips/4,  % +Robot, +Warmup, +Count, +Options
            bench_params_round_trips/4, % +Robot, +Warmup, +Count, +Options
            bench_result/1              % -Result
          ]).
:- use_module(robot_bridge, [read_table/3, write_table/3, read_params/3, write_params/3]).
:- autoload(library(error), [must_be/2]).

/** <module> Agent side of `dfrl bench bridge`

An agent-like thread times read_table/3 followed by write_table/3 (of the
table it just read), or read_params/3 followed by write_params/3, while the
host's control loop serves it.
*/

:- dynamic result_/1.

%!  bench_table_round_trips(+Robot, +Warmup, +Count, +Options) is det.
%
%   Run Warmup untimed, then Count timed read+write pairs on Robot, and
%   record bench(Total, Get, Set), three lists of milliseconds, for
%   bench_result/1. Options are passed to read_table/3 and write_table/3.
%   An exception is recorded as error(E).

bench_table_round_trips(Robot, Warmup, Count, Options) :-
    round_trips(table, Robot, Warmup, Count, Options).

%!  bench_params_round_trips(+Robot, +Warmup, +Count, +Options) is det.
%
%   As bench_table_round_trips/4 with read_params/3 and write_params/3 (of
%   the parameters just read).

bench_params_round_trips(Robot, Warmup, Count, Options) :-
    round_trips(params, Robot, Warmup, Count, Options).

round_trips(What, Robot, Warmup, Count, Options) :-
    must_be(nonneg, Warmup),
    must_be(nonneg, Count),
    retractall(result_(_)),
    catch(( forall(between(1, Warmup, _), pair(What, Robot, Options, _, _)),
            findall(T-G-S, ( between(1, Count, _),
                             pair(What, Robot, Options, G, S),
                             T is G + S ), Triples),
            pairs(Triples, Ts, Gs, Ss),
            Result = bench(Ts, Gs, Ss)
          ),
          E, Result = error(E)),
    assertz(result_(Result)).

pair(What, Robot, Options, GetMs, SetMs) :-
    get_time(T0),
    get(What, Robot, Got, Options),
    get_time(T1),
    set(What, Robot, Got, Options),
    get_time(T2),
    GetMs is (T1 - T0) * 1000,
    SetMs is (T2 - T1) * 1000.

get(table, Robot, Table, Options) :-
    read_table(Robot, Table, Options).
get(params, Robot, Params, Options) :-
    read_params(Robot, Params, Options).

set(table, Robot, Table, Options) :-
    write_table(Robot, Table, Options).
set(params, Robot, params(Layout, _, Values), Options) :-
    write_params(Robot, params(Layout, Values), Options).

pairs([], [], [], []).
pairs([T-G-S|R], [T|Ts], [G|Gs], [S|Ss]) :-
    pairs(R, Ts, Gs, Ss).

%!  bench_result(-Result) is semidet.
%
%   Result of the finished run (and forget it); fails while it runs.

bench_result(Result) :-
    retract(result_(Result)).
