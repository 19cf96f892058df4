:- module(bounds_monitor,
          [ monitor_call_started/7,     % +Id, +Node, +Agent, +Module, +Thread, +CPU0, +Limits
            monitor_call_ended/2,       % +Id, -Signalled
            monitor_park/1,             % +Id
            monitor_unpark/1,           % +Id
            monitor_stop_call/3,        % +Id, +Thread, +Kind
            monitor_reclaim/0,
            note_module_size/3,         % +Node, +Agent, +Bytes
            admit_memory/3,             % +Node, +Agent, +Module
            bounds_node_memory/2        % +Node, -Bytes
          ]).
%   Eager imports (not autoload/2): see node_connection.pl.
:- use_module(library(aggregate), [aggregate_all/3]).
:- use_module(library(apply), [foldl/4]).
:- use_module(library(lists), [sum_list/2, member/2, max_list/2]).
:- use_module(library(debug), [debug/3]).
:- use_module(node, [node_option/3]).
:- use_module(worker_pool, [pool_signal/3]).
:- use_module(node_memory, [node_memory_note_idle/0, node_memory_check/2]).
:- use_module(bounds_ledger, [bounds_warning/2, stat_add/2, stat_set/2, stat_max/2]).
:- use_module(bounds_limits,
              [limit/3, over/2, module_size/2, check_module_size/2, thread_stacks/2]).
:- use_module(bounds_slots, [slots_sweep_peers/0]).
:- use_module(bounds_idle, [idle_note_active/2, idle_due/1, idle_expire/0]).
:- use_module(bounds_reclaim,
              [reclaim_plan/0, reclaim_due/1, reclaim_if_due/0, reclaim_threshold/1]).

/** <module> The bounds monitor: running calls checked while they run

The per-call bounds of agent_bounds.pl that cannot be checked where the
agent's code runs: CPU time, wall time (less time parked), time parked,
the size of the agent's module, the node's agent_memory_budget and the
process's resident memory. This module keeps the running bounded calls
(registered by agent_bounds.pl as they start and end), the last measured
module sizes of the agents, and the monitor thread.

The monitor is one thread per process (`dfrl_bounds_monitor`, started on
the first bounded call). It wakes every `dfrl_bounds_period` seconds
(flag, 0.2) while calls run; when none does, it waits on its queue until
the first idle clock runs out (agent_idle_limit, bounds_idle.pl), at
most 10 s; a tick reads each running call's thread CPU time (about 0.6
us) and the size of its agent's module. It also runs the reclaim passes
(bounds_reclaim.pl) and removes agents idle too long.

A call over a bound is stopped: '$dfrl_bound'(Kind) is thrown in its
thread (thread_signal/2). A thread that keeps running after the signal
is signalled again every `dfrl_bounds_grace` seconds (flag, 0.5), ten
times at most; then the agent is purged and a warning says the thread
did not stop.
*/

:- create_prolog_flag(dfrl_bounds_period, 0.2, [type(float), keep(true)]).
:- create_prolog_flag(dfrl_bounds_grace, 0.5, [type(float), keep(true)]).

:- dynamic
    call_/7,                    % Id, Node, Agent, Module, Thread, CPU0, Limits
    signalled_/4,               % Id, Kind, Time, Tries
    call_time_/4,               % Id, Start, Parked (s so far), ParkedSince|none
    monitor_/2,                 % Thread, Queue
    monitor_idle_/0,            % the monitor waits for a call to start
    monitor_hot_/0,             % a node's agents hold over half its budget
    module_size_/3,             % Node, Agent, Bytes (last measured)
    tick_size_/2.               % Id, Bytes: module size this tick

:- thread_local
    running_/1.                 % Id: this thread runs bounded call Id

:- multifile
    node:node_stopping/1,
    agents:agent_changed/3.

max_signals(10).

		 /*******************************
		 *        RUNNING CALLS		*
		 *******************************/

%!  monitor_call_started(+Id, +Node, +Agent, +Module, +Thread, +CPU0, +Limits) is det.
%
%   Bounded call Id of Agent (code in Module) on Node starts in Thread
%   (this thread), whose CPU time was CPU0, with Limits: the monitor
%   checks it from now on.

monitor_call_started(Id, Node, Agent, Module, Thread, CPU0, Limits) :-
    assertz(running_(Id)),
    (   call_(_, _, _, _, _, _, _) -> true ; node_memory_note_idle ),
    get_time(Start),
    with_mutex(dfrl_bounds, assertz(call_time_(Id, Start, 0, none))),
    assertz(call_(Id, Node, Agent, Module, Thread, CPU0, Limits)),
    monitor_wake.

%!  monitor_call_ended(+Id, -Signalled) is det.
%
%   Bounded call Id ended (in its own thread). Signalled is the Kind of
%   the bound it was signalled for, or `none`: a call that ended
%   normally after its signal had caught it.

monitor_call_ended(Id, Signalled) :-
    retractall(running_(Id)),
    (   retract(call_(Id, Node, Agent, _, Me, CPU0, _))
    ->  catch(( thread_statistics(Me, cputime, CPU1),
                Used is CPU1 - CPU0,
                stat_max(peak_cpu(Node), Used)
              ), _, true),
        idle_note_active(Node, Agent)
    ;   true
    ),
    with_mutex(dfrl_bounds, retractall(call_time_(Id, _, _, _))),
    (   retract(signalled_(Id, Kind, _, _))
    ->  Signalled = Kind
    ;   Signalled = none
    ).

%!  monitor_park(+Id) is det.
%!  monitor_unpark(+Id) is det.
%
%   Call Id parks (bounds_park/1) and comes back: time parked counts
%   for agent_idle_limit, not agent_wall_limit.

monitor_park(Id) :-
    get_time(Now),
    with_mutex(dfrl_bounds,
               (   retract(call_time_(Id, Start, Parked, _))
               ->  assertz(call_time_(Id, Start, Parked, Now))
               ;   true
               )).

monitor_unpark(Id) :-
    get_time(Now),
    with_mutex(dfrl_bounds,
               (   retract(call_time_(Id, Start, Parked0, Since)),
                   number(Since)
               ->  Parked is Parked0 + Now - Since,
                   assertz(call_time_(Id, Start, Parked, none))
               ;   true
               )).

%!  monitor_stop_call(+Id, +Thread, +Kind) is det.
%
%   Stop call Id, running in Thread, for going over bound Kind: throw
%   '$dfrl_bound'(Kind) in it (once; the monitor signals again if it
%   keeps running).

monitor_stop_call(Id, Thread, Kind) :-
    get_time(Now),
    with_mutex(dfrl_bounds,
               (   signalled_(Id, _, _, _)
               ->  New = false
               ;   assertz(signalled_(Id, Kind, Now, 1)),
                   New = true
               )),
    (   New == true
    ->  pool_signal(agents, Thread, bounds_monitor:stop_if_running(Id, Kind))
    ;   true
    ).

%   The signal: stop the call Id if this thread still runs it.
stop_if_running(Id, Kind) :-
    (   running_(Id)
    ->  throw('$dfrl_bound'(Kind))
    ;   true
    ).

		 /*******************************
		 *            MONITOR		*
		 *******************************/

%   Called after the call is registered: the monitor marks itself idle
%   before it looks for calls, so one of the two sees the other.
monitor_wake :-
    (   monitor_(_, Queue)
    ->  true
    ;   with_mutex(dfrl_bounds_monitor, monitor_start(Queue))
    ),
    (   monitor_idle_
    ->  thread_send_message(Queue, wake)
    ;   true
    ).

monitor_start(Queue) :-
    (   monitor_(_, Queue)
    ->  true
    ;   message_queue_create(Queue),
        thread_create(monitor_loop(Queue), Tid,
                      [alias(dfrl_bounds_monitor), detached(true)]),
        assertz(monitor_(Tid, Queue))
    ).

%   Block while no call runs and no reclaim is due; tick every period
%   while calls run, five times as often while a node's agents hold over
%   half its agent_memory_budget.
monitor_loop(Queue) :-
    assertz(monitor_idle_),
    get_time(Now),
    (   call_(_, _, _, _, _, _, _)
    ->  retractall(monitor_idle_),
        current_prolog_flag(dfrl_bounds_period, Period0),
        (   monitor_hot_
        ->  Period1 is Period0 / 5
        ;   Period1 = Period0
        )
    ;   idle_poll(Period1)
    ),
    (   aggregate_all(min(T), ( reclaim_due(T) ; idle_due(T) ), Due)
    ->  Wait is max(0, Due - Now),
        (   Period1 == infinite -> Period = Wait ; Period is min(Period1, Wait) )
    ;   Period = Period1
    ),
    (   Period == infinite
    ->  thread_get_message(Queue, _)
    ;   thread_get_message(Queue, _, [timeout(Period)])
    ->  true
    ;   true
    ),
    retractall(monitor_idle_),
    drain(Queue),
    catch(monitor_tick, E, print_message(warning, E)),
    catch(reclaim_if_due, E2, print_message(warning, E2)),
    catch(( slots_sweep_peers, idle_expire ), E3, print_message(warning, E3)),
    monitor_loop(Queue).

%   With no call running, the monitor still wakes every 10 s (about
%   0.2 ms) to find agents from peers that arrived since (their idle
%   clocks, agent_idle_limit): an arrival does not wake it, the agent's
%   first handler call does (every arriving agent is started), and an
%   agent installed and never started is found by this wake.
idle_poll(10.0).

drain(Queue) :-
    (   thread_get_message(Queue, _, [timeout(0)])
    ->  drain(Queue)
    ;   true
    ).

monitor_tick :-
    retractall(tick_size_(_, _)),
    get_time(Now),
    forall(call_(Id, Node, Agent, Module, Thread, CPU0, Limits),
           catch(check_call(call(Id, Node, Agent, Module, Thread, CPU0, Limits), Now),
                 E, debug(dfrl(bounds), 'check ~w: ~p', [Id, E]))),
    findall(Node, call_(_, Node, _, _, _, _, _), Nodes0),
    sort(Nodes0, Nodes),
    foldl(check_budget, Nodes, false, Hot0),
    check_rss(Nodes, Hot0, Hot),
    retractall(monitor_hot_),
    (   Hot == true -> assertz(monitor_hot_) ; true ),
    thread_self(Me),
    thread_statistics(Me, cputime, Own),
    stat_set(monitor_cpu, Own),
    stat_add(ticks, 1).

%   Call is call(Id, Node, Agent, Module, Thread, CPU0, Limits), as in call_/7.
check_call(call(Id, Node, Agent, _Module, Thread, _, _), Now) :-
    signalled_(Id, Kind, Since, Tries),
    !,
    current_prolog_flag(dfrl_bounds_grace, Grace),
    max_signals(Max),
    (   Now - Since < Grace
    ->  true
    ;   integer(Tries),
        Tries < Max
    ->  T1 is Tries + 1,
        with_mutex(dfrl_bounds,
                   ( retract(signalled_(Id, Kind, Since, Tries)),
                     assertz(signalled_(Id, Kind, Now, T1)) )),
        stat_add(resignals, 1),
        pool_signal(agents, Thread, bounds_monitor:stop_if_running(Id, Kind))
    ;   Tries == Max
    ->  with_mutex(dfrl_bounds,
                   ( retract(signalled_(Id, Kind, Since, Tries)),
                     assertz(signalled_(Id, Kind, Now, gave_up)) )),
        bounds_warning(Node, dfrl_bounds(unstoppable(Node, Agent, Kind, Max))),
        catch(agents:agent_purge(Node, Agent), _, true)
    ;   true
    ).
check_call(call(Id, Node, _Agent, Module, Thread, CPU0, Limits), Now) :-
    thread_statistics(Thread, cputime, CPU),
    Used is CPU - CPU0,
    catch(( thread_statistics(Thread, globalused, G),
            thread_statistics(Thread, localused, L),
            thread_statistics(Thread, trailused, T),
            Stack is G + L + T,
            stat_max(peak_stack(Node), Stack) ), _, true),
    limit(Limits, cpu, MaxCPU),
    limit(Limits, module, MaxModule),
    limit(Limits, wall, MaxWall),
    limit(Limits, idle, MaxParked),
    wall_times(Id, Now, Held, Parked),
    (   over(Used, MaxCPU)
    ->  monitor_stop_call(Id, Thread, cpu(MaxCPU))
    ;   over(Held, MaxWall)
    ->  stat_add(wall_stops, 1),
        monitor_stop_call(Id, Thread, wall(MaxWall))
    ;   over(Parked, MaxParked)
    ->  stat_add(wall_stops, 1),
        monitor_stop_call(Id, Thread, idle(MaxParked))
    ;   MaxModule \== infinite,
        tick_module_size(Id, Module, Size),
        over(Size, MaxModule)
    ->  monitor_stop_call(Id, Thread, module_memory(MaxModule))
    ;   true
    ).

%   agent_wall_limit: the seconds call Id held a slot (since it started,
%   less the time it was parked with bounds_park/1) and, for
%   agent_idle_limit, the seconds it was parked in all.
wall_times(Id, Now, Held, Parked) :-
    (   call_time_(Id, Start, Parked0, Since)
    ->  (   number(Since)
        ->  Parked is Parked0 + Now - Since
        ;   Parked = Parked0
        ),
        Held is Now - Start - Parked
    ;   Held = 0,
        Parked = 0
    ).

%   A module's size, measured once per tick: predicate_property(size(B))
%   walks the clauses (about 10 ms for 700,000 facts).
tick_module_size(Id, Module, Size) :-
    (   tick_size_(Id, S0)
    ->  Size = S0
    ;   module_size(Module, Size),
        assertz(tick_size_(Id, Size))
    ).

%   agent_memory_budget(B): the node's agents may hold B bytes, counted
%   as the sizes of their modules plus the stacks of the threads running
%   their calls. Over it, the running call that holds most (stack plus
%   module) is stopped with memory_budget(B); calls already signalled
%   count as freed.
check_budget(Node, Hot0, Hot) :-
    node_option(Node, agent_memory_budget, Budget),
    (   Budget == infinite
    ->  Hot = Hot0
    ;   findall(c(Id, Thread, Mem, Sig),
                ( call_(Id, Node, _, Module, Thread, _, _),
                  catch(( thread_stacks(Thread, Stack),
                          tick_module_size(Id, Module, Size),
                          Mem is Stack + Size ), _, fail),
                  ( signalled_(Id, _, _, _) -> Sig = true ; Sig = false )
                ),
                Calls),
        findall(A, call_(_, Node, A, _, _, _, _), Running),
        idle_memory(Node, Running, Idle),
        aggregate_all(sum(M), member(c(_, _, M, _), Calls), Run),
        aggregate_all(sum(M), member(c(_, _, M, true), Calls), Going),
        Used is Idle + Run,
        stat_max(peak_memory(Node), Used),
        (   Used - Going > Budget,
            aggregate_all(max(M, Id-T), member(c(Id, T, M, false), Calls),
                          max(_, BigId-BigThread))
        ->  stat_add(budget_stops, 1),
            monitor_stop_call(BigId, BigThread, memory_budget(Budget))
        ;   true
        ),
        (   Used * 2 > Budget -> Hot = true ; Hot = Hot0 )
    ).

%   The process's RSS over its baseline + the largest budget of the
%   nodes running calls (node_memory.pl): work done in C (atoms, GMP,
%   memory streams) is not in the count above. Over it, the running call
%   that has used most CPU is stopped with memory_budget(B), one a tick.
check_rss(Nodes, Hot0, Hot) :-
    findall(B, ( member(N, Nodes),
                 node_option(N, agent_memory_budget, B),
                 B \== infinite ), Bs),
    (   Bs == []
    ->  Hot = Hot0
    ;   max_list(Bs, Budget),
        node_memory_check(Budget, Verdict),
        (   Verdict = over(Rss, _)
        ->  stat_max(peak_rss, Rss),
            (   aggregate_all(max(Used, Id-T),
                              ( call_(Id, _, _, _, T, CPU0, _),
                                \+ signalled_(Id, _, _, _),
                                catch(thread_statistics(T, cputime, C), _, fail),
                                Used is C - CPU0 ),
                              max(_, BigId-BigT))
            ->  stat_add(rss_stops, 1),
                monitor_stop_call(BigId, BigT, memory_budget(Budget))
            ;   true
            ),
            Hot = true
        ;   Verdict = near(_, _)
        ->  Hot = true
        ;   Hot = Hot0
        )
    ).

call_memory(Module, Thread, Mem) :-
    thread_stacks(Thread, Stack),
    module_size(Module, Size),
    Mem is Stack + Size.

%   Modules of the agents of Node that run no call, as last measured.
idle_memory(Node, Running, Idle) :-
    aggregate_all(sum(S),
                  ( module_size_(Node, A, S),
                    \+ memberchk(A, Running)
                  ),
                  Idle).

%!  bounds_node_memory(+Node, -Bytes) is det.
%
%   Bytes the agents of Node hold as agent_memory_budget counts them:
%   their modules (as last measured: on arrival, at the end of each
%   call, running calls now) plus the stacks of the threads running
%   their calls.

bounds_node_memory(Node, Bytes) :-
    findall(Mem,
            ( call_(_, Node, _, Module, Thread, _, _),
              catch(call_memory(Module, Thread, Mem), _, fail)
            ),
            Mems),
    sum_list(Mems, Run),
    findall(A, call_(_, Node, A, _, _, _, _), Running),
    idle_memory(Node, Running, Idle),
    Bytes is Idle + Run.

%!  note_module_size(+Node, +Agent, +Bytes) is det.
%
%   The module of Agent, still on Node, measured Bytes.

note_module_size(Node, Agent, Size) :-
    with_mutex(dfrl_bounds,
               (   agents:agent_exists(Node, Agent)
               ->  retractall(module_size_(Node, Agent, _)),
                   assertz(module_size_(Node, Agent, Size))
               ;   true
               )).

%!  admit_memory(+Node, +Agent, +Module) is det.
%
%   Agent arrives on Node with its code in Module: Module must be within
%   agent_module_limit and fit in what is left of agent_memory_budget
%   (counted and noted under one mutex).
%
%   @error resource_error(agent_memory)

admit_memory(Node, Name, Module) :-
    module_size(Module, Size),                  % measured once
    check_module_size(Node, Size),
    node_option(Node, agent_memory_budget, Budget),
    with_mutex(dfrl_bounds, admit_memory(Node, Name, Size, Budget, Verdict)),
    (   Verdict = over(Used)
    ->  bounds_warning(Node, dfrl_bounds(refused(Node, agent_memory, Budget))),
        throw(error(resource_error(agent_memory),
                    context(_, budget(Used, Size, Budget))))
    ;   true
    ).

admit_memory(Node, Name, Size, Budget, Verdict) :-
    (   Budget \== infinite,
        bounds_node_memory(Node, Used),
        Used + Size > Budget
    ->  Verdict = over(Used)
    ;   retractall(module_size_(Node, Name, _)),
        assertz(module_size_(Node, Name, Size)),
        Verdict = ok
    ).

%!  monitor_reclaim is det.
%
%   An agent that held much memory left: plan the reclaim passes
%   (bounds_reclaim.pl) and wake the monitor for them.

monitor_reclaim :-
    reclaim_plan,
    (   monitor_(_, Queue)
    ->  thread_send_message(Queue, wake)
    ;   with_mutex(dfrl_bounds_monitor, monitor_start(Queue)),
        thread_send_message(Queue, wake)
    ).

agents:agent_changed(removed, Node, Agent) :-
    (   with_mutex(dfrl_bounds, retract(module_size_(Node, Agent, Size))),
        reclaim_threshold(Big),
        Size >= Big
    ->  monitor_reclaim
    ;   true
    ).

node:node_stopping(Node) :-
    with_mutex(dfrl_bounds, retractall(module_size_(Node, _, _))).
