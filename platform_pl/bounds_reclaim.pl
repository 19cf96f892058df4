:- module(bounds_reclaim,
          [ reclaim_plan/0,
            reclaim_due/1,              % -Time
            reclaim_if_due/0,
            reclaim_threshold/1         % -Bytes
          ]).
%   Eager imports (not autoload/2): see node_connection.pl.
:- use_module(library(lists), [member/2]).
:- use_module(bounds_ledger, [stat_add/2]).

/** <module> Giving the memory of stopped agents back to the OS

After an agent that held much memory left (stopped, or a module of
16 MiB or more), its retracted clauses are reclaimed and the freed
heap given back to the OS (garbage_collect_clauses/0, trim_heap/0),
in the monitor thread, 0.3 s later (the stopped call's worker has
usually exited by then) and again 2, 6 and 15 s later: on a loaded
machine a worker can take seconds to exit, and while it has not,
clause garbage collection frees nothing (seen in a full test run
beside stress-ng --cpu 2: 8 stopped assert bombs left +591 MiB after
the 0.3 and 2 s passes). SWI-Prolog 9.0.4 frees erased
clauses over several passes (measured: 8 modules of 700,000 facts,
retractall/1, then garbage_collect_clauses/0 every 0.1 s: the
clause count fell over 3 to 4 passes; one pass and trim_heap gave
back 85 of 707 MB, passes until no progress and then trim_heap all
but 5 MB). So a reclaim repeats a pass every 0.1 s while the number
of clauses falls (at most 50 passes), then trims the heap.

The passes run in the monitor thread of agent_bounds.pl
(bounds_monitor.pl), which asks reclaim_due/1 when to wake.
*/

:- dynamic
    reclaim_due_/1,             % Time: give freed memory back then
    reclaim_pass_/1.            % passes of the current reclaim so far

%!  reclaim_threshold(-Bytes) is det.
%
%   An agent whose module held Bytes or more is reclaimed when it
%   leaves.

reclaim_threshold(16777216).
max_reclaim_passes(50).

reclaim_after([0.3, 2.0, 6.0, 15.0]).

%!  reclaim_plan is det.
%
%   Plan the passes of a reclaim (0.3, 2, 6 and 15 s from now; a pass
%   already due within 0.25 s of one of them does for it). The caller
%   wakes the monitor.

reclaim_plan :-
    get_time(Now),
    reclaim_after(Delays),
    findall(T, ( member(D, Delays), T is Now + D ), Times),
    with_mutex(dfrl_bounds,
               forall(member(T, Times),
                      (   reclaim_due_(T0), abs(T0 - T) < 0.25
                      ->  true
                      ;   assertz(reclaim_due_(T))
                      ))).

%!  reclaim_due(-Time) is nondet.
%
%   A pass is due at Time.

reclaim_due(Time) :-
    reclaim_due_(Time).

%!  reclaim_if_due is det.
%
%   Run a pass if one is due: collect clause garbage, and while that
%   frees clauses plan another 0.1 s later (at most 50); then collect
%   atoms and trim the heap.

reclaim_if_due :-
    get_time(Now),
    with_mutex(dfrl_bounds,
               findall(T, ( reclaim_due_(T), T =< Now, retract(reclaim_due_(T)) ), Due)),
    (   Due == []
    ->  true
    ;   statistics(clauses, C0),
        garbage_collect_clauses,
        statistics(clauses, C1),
        (   retract(reclaim_pass_(P0)) -> true ; P0 = 0 ),
        P is P0 + 1,
        max_reclaim_passes(MaxP),
        (   C1 < C0,
            P < MaxP
        ->  assertz(reclaim_pass_(P)),
            Next is Now + 0.1,
            with_mutex(dfrl_bounds, assertz(reclaim_due_(Next)))
        ;   garbage_collect_atoms,          % atoms a stopped call made
            trim_heap,
            stat_add(reclaims, 1)
        )
    ).
