:- module(memory_robots,
          [ memory_robots_start/1,      % +Robot-Values pairs
            memory_robots_stop/0,
            memory_robot_table/2,       % ?Robot, ?Values
            memory_robot_sets/2,        % ?Robot, ?Count
            memory_robot_delay/2,       % +Robot, +Seconds
            memory_robot_options/3,     % ?Robot, ?Op, ?Options
            memory_robot_history/2      % +Robot, +CsvFile
          ]).
/** <module> Robots with in-memory tables, for the platform's tests

A plain-Prolog implementation of the resource hook
(platform_pl/robot_resources.pl): each robot has a table of 2 actions
held in this module; reads return it, writes replace it and are counted
(a write that is not qtable(Shape, List) raises type_error(qtable, T)).
Visit counts are all 1.0. A robot may be made slow (memory_robot_delay/2:
each read waits that long first, so an agent stays on its node), and the
options of the last read and write of each robot are kept
(memory_robot_options/3), so tests can check where a request came from.
*/
:- use_module('../../platform_pl/robot_resources', []).
:- autoload(library(apply), [maplist/3]).
:- autoload(library(lists), [member/2, memberchk/2]).
:- autoload(library(error), [must_be/2]).

:- dynamic table_/2, sets_/2, delay_/2, options_/3, history_/2.

:- multifile
    robot_resources:robot/2,
    robot_resources:table_get/3,
    robot_resources:tables_get/4,
    robot_resources:table_set/3.

%!  memory_robots_start(+Robots) is det.
%
%   Host exactly Robots, a list Robot-Values (flat values, 2 actions).

memory_robots_start(Robots) :-
    memory_robots_stop,
    forall(member(R-V, Robots),
           ( assertz(table_(R, V)), assertz(sets_(R, 0)) )).

%!  memory_robots_stop is det.
%
%   Host no robots.

memory_robots_stop :-
    retractall(table_(_, _)),
    retractall(sets_(_, _)),
    retractall(delay_(_, _)),
    retractall(options_(_, _, _)).

%!  memory_robot_delay(+Robot, +Seconds) is det.
%
%   Every later read of Robot's table first waits Seconds.

memory_robot_delay(R, S) :-
    must_be(number, S),
    retractall(delay_(R, _)),
    assertz(delay_(R, S)).

%!  memory_robot_options(?Robot, ?Op, ?Options) is nondet.
%
%   Options came with the last request Op (get or set) for Robot.

memory_robot_options(R, Op, O) :-
    options_(R, Op, O).

seen(R, Op, O) :-
    (   delay_(R, S), Op == get -> sleep(S) ; true ),
    retractall(options_(R, Op, _)),
    assertz(options_(R, Op, O)).

%!  memory_robot_table(?Robot, ?Values) is nondet.

%!  memory_robot_history(+Robot, +CsvFile) is det.
%
%   Every later write of Robot appends a row to CsvFile, in the columns
%   of a robot process's shares_<robot>.csv (robot, share_index,
%   iteration, wall_time, digest, round, agent, epoch: the write's
%   options; the digest is the SHA-1 of the values), so that the history
%   checker reads it as it reads a run's.

memory_robot_history(R, File) :-
    retractall(history_(R, _)),
    assertz(history_(R, File)),
    setup_call_cleanup(open(File, write, Out),
                       format(Out, "robot,share_index,iteration,wall_time,digest,round,agent,epoch~n", []),
                       close(Out)).

note_history(R, N, V, O) :-
    (   history_(R, File)
    ->  get_time(T),
        variant_sha1(V, Digest),
        option_or_empty(round, O, Round),
        option_or_empty(agent, O, Agent),
        option_or_empty(epoch, O, Epoch),
        setup_call_cleanup(open(File, append, Out),
                           format(Out, "~w,~w,0,~6f,~w,~w,~w,~w~n",
                                  [R, N, T, Digest, Round, Agent, Epoch]),
                           close(Out))
    ;   true
    ).

option_or_empty(Name, Options, Value) :-
    Opt =.. [Name, V],
    (   memberchk(Opt, Options) -> Value = V ; Value = '' ).

memory_robot_table(R, V) :-
    table_(R, V).

%!  memory_robot_sets(?Robot, ?Count) is nondet.
%
%   Count is the number of writes Robot's table had.

memory_robot_sets(R, N) :-
    sets_(R, N).

shape(V, [A, 2]) :-
    length(V, N),
    A is N // 2.

robot_resources:robot(R, [algo(test), shape(S)]) :-
    table_(R, V),
    shape(V, S).
robot_resources:table_get(R, qtable(S, V), O) :-
    seen(R, get, O),
    table_(R, V),
    shape(V, S).
robot_resources:tables_get(R, qtable(S, V), qtable(S, W), O) :-
    seen(R, get, O),
    table_(R, V),
    shape(V, S),
    maplist([_, 1.0]>>true, V, W).
robot_resources:table_set(R, T, O) :-
    seen(R, set, O),
    (   T = qtable(_, V), is_list(V)
    ->  true
    ;   throw(error(type_error(qtable, T), _))
    ),
    with_mutex(memory_robots,
               ( retract(table_(R, _)),
                 assertz(table_(R, V)),
                 retract(sets_(R, N)),
                 N1 is N + 1,
                 assertz(sets_(R, N1)),
                 note_history(R, N1, V, O) )).
