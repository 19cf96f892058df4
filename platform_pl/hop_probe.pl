:- module(hop_probe,
          [ hop_probe/1,                % +Point
            hop_probe_stamps/1          % -Stamps
          ]).

/** <module> Time stamps along a hop, compiled in only for the benchmark

The platform's modules on the path of a hop (migration.pl,
migration_arrival.pl, node_connection.pl, agent_execution.pl) mark points of it with the goal
hop_probe(Point). When the process that loads the platform has the
environment variable DFRL_HOP_PROBE set (to anything but `0`), each
such goal is compiled to a call that records Point and the time
(get_time/1; a frame read or answered is recorded by its request's
name); otherwise it is compiled to `true` and costs nothing.
`dfrl bench migrate --timeline` sets the variable in its two node
processes and reads the stamps (hop_probe_stamps/1, called
by bench_migrate.pl at the end) to show where a hop's time goes, at a
cost of one assertz/1 a point (some 2 us) instead of the some 10 us a
call of step_trace.pl's wrappers (library(prolog_wrap)) costs.

Only the four modules above are expanded: code compiled in any other
module (an agent's, a user's) keeps hop_probe/1 as a plain call, which
records nothing unless the variable is set.
*/

:- dynamic stamp_/2.                    % Point, Time

probing :-
    getenv('DFRL_HOP_PROBE', V),
    V \== '',
    V \== '0'.

probed_module(migration).
probed_module(migration_arrival).
probed_module(node_connection).
probed_module(agent_execution).

:- multifile system:goal_expansion/2.

system:goal_expansion(hop_probe(Point), Goal) :-
    prolog_load_context(module, M),
    probed_module(M),
    (   probing
    ->  Goal = hop_probe:stamp(Point)
    ;   Goal = true
    ).

%!  hop_probe(+Point) is det.
%
%   Record Point now (if DFRL_HOP_PROBE is set). Calls in the probed
%   modules never reach this: they are compiled away or to stamp/1.

hop_probe(Point) :-
    (   probing
    ->  stamp(Point)
    ;   true
    ).

stamp(Point0) :-
    get_time(T),
    point_name(Point0, Point),
    assertz(stamp_(Point, T)).

%   A frame read or answered is named by its request's functor
%   (frame_read(transfer), replied(commit)): the frame itself may hold
%   100,000 floats, and the reader of the stamps must tell a transfer
%   from the hello of a new connection.
point_name(frame_read(frame(_, Term)), frame_read(F)) :-
    !,
    request_name(Term, F).
point_name(frame_read(_), frame_read(end_of_file)) :-
    !.
point_name(replied(Request), replied(F)) :-
    !,
    request_name(Request, F).
point_name(Point, Point).

request_name(Term, F) :-
    (   compound(Term)
    ->  compound_name_arity(Term, F, _)
    ;   atom(Term)
    ->  F = Term
    ;   F = other
    ).

%!  hop_probe_stamps(-Stamps) is det.
%
%   Stamps are the points recorded so far, stamp(Point, Time) in the
%   order they were recorded; they are forgotten.

hop_probe_stamps(Stamps) :-
    findall(stamp(P, T), retract(stamp_(P, T)), Stamps).
