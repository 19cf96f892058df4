:- module(agent_bounds,
          [ bounds_call/4,              % +Node, +Agent, +Module, :Goal
            bounds_stopped/3,           % +Node, +Agent, +Kind
            bounds_admit/3,             % +Node, +Mode, +Agents
            bounds_arrived/3,           % +Node, +Agent, +Source
            bounds_install/4,           % +Node, +Record, +Status, -Name
            bounds_install/5,           % +Node, +Record, +Status, -Name, +Peer
            bounds_arrived/4,           % +Node, +Agent, +Source, +Peer
            bounds_peer/2,              % +Ctx, -Peer
            bounds_peer/3,              % +Ctx, +Claim, -Peer
            bounds_peer_post/2,         % +Ctx, +Link
            bounds_park/1,              % :Goal
            bounds_stop_ball/1,         % @Exception
            bounds_node_memory/2,       % +Node, -Bytes
            bounds_post/0,
            bounds_warning/2,           % +Node, +Message
            agent_bound_report/3,       % ?Node, ?Agent, ?Report
            bounds_statistics/1         % -Stats
          ]).
%   Eager imports (not autoload/2): see node_connection.pl.
:- use_module(library(prolog_stream), [open_prolog_stream/4]).
:- use_module(library(aggregate), [aggregate_all/3]).
:- use_module(library(apply), [foldl/4]).
:- use_module(library(lists), [sum_list/2, member/2, max_list/2]).
:- use_module(library(debug), [debug/3]).
:- use_module(node,
              [ node_option/3, node_property/2, node_for_address/2,
                with_node/2, ctx_node/2, ctx_peer/2, ctx_peer_name/2 ]).
:- use_module(transport, [transport_request/4]).
:- use_module(worker_pool, [pool_run/3, pool_signal/3, pool_retire/0]).
:- use_module(node_memory, [node_memory_note_idle/0, node_memory_check/2]).
:- use_module(bounds_ledger,
              [ window_take/4, window_forget/1, window_live/1, windows_prune/2,
                windows_forget_node/1, bounds_warning/2,
                stat_add/2, stat_set/2, stat_max/2, bounds_statistics/1 ]).

:- meta_predicate
    bounds_call(+, +, +, 0),
    bounds_park(0).

/** <module> Bounds on what an agent may take from a node

A node runs code that peers send it (checked by the sandbox, which says
*what* it may call, not *how much*). This module bounds how much, per
handler call of an agent (its main handler or a posted event, in a pool
worker):

  | bound            | node option                     | default   | measured by |
  |------------------|---------------------------------|-----------|-------------|
  | CPU time         | agent_cpu_limit(Sec)            | 2 s       | the thread's CPU time since the call started (monitor) |
  | stacks           | agent_stack_limit(Bytes)        | 256 MiB   | SWI-Prolog's own per-thread stack_limit flag |
  | its own module   | agent_module_limit(Bytes)       | 64 MiB    | predicate_property(size(B)) summed (monitor, end of call, arrival) |
  | posts it sends   | agent_post_limit(PerMinute)     | 600       | counted in agent_post/6 |
  | output lines     | agent_log_limit(PerMinute)      | 200       | user_output / user_error of the call go through a counting stream |

and per node: agents present (`max_agents(N)`, default 100, counted
under the registry mutex with the install) and agents arriving as
clones (`clone_limit(PerMinute)`, default 60). An arrival over either is
refused at the transfer with resource_error(agents) or
resource_error(clones), which the sender's agent_move/3 or
agent_clone/4 raises. Memory of the node as a whole:

  | bound            | node option                     | default   | measured by |
  |------------------|---------------------------------|-----------|-------------|
  | agents together  | agent_memory_budget(Bytes)      | 1 GiB     | module sizes (last measured) + allocated stacks of running calls (monitor, arrival) |
  | calls at once    | max_running_agents(N)           | 8         | N slots; a call waits agent_slot_wait(Sec) (60) for one |

A slot costs wall time, and one peer (bounds_peer/3: its TLS
certificate's name, else its IP address and the node address it claims)
cannot take a node from the others:

  | bound               | node option                  | default  | measured by |
  |---------------------|------------------------------|----------|-------------|
  | slot held           | agent_wall_limit(Sec)        | 60 s     | wall time of the call less time parked (monitor) |
  | idle, or parked     | agent_idle_limit(Sec)        | 600 s    | since an agent from a peer last ran (monitor); a call's parked time |
  | agents of a peer    | max_agents_per_peer(N)       | 50       | counted with max_agents, under the registry mutex |
  | slots of a peer     | max_running_per_peer(N)      | 4        | a queue of N tokens per node and peer, taken before the node's |
  | posts from a peer   | peer_post_limit(PerMinute)   | 6000     | counted as a post request arrives (bounds_peer_post/1) |

Node code that waits in a handler call (the dFRL agent's rest, robot
calls, tree-round messages) parks with bounds_park/1: its slots are
free meanwhile. Arriving code cannot park (it is not in the agent API).

so the stacks of agents never exceed N x agent_stack_limit, and what
they hold is kept near the budget (README "Bounds on agents" has the
measurements). The budget also bounds the process's resident memory
(node_memory.pl): over its baseline + the budget, the running call that
has used most CPU is stopped, one a tick; this catches what C code
allocates outside stacks and modules, write by write. Sizes of single C
calls are checked before them (guest_limits.pl). Every bound takes
`infinite`.

An agent over a per-call bound is stopped: the term '$dfrl_bound'(Kind)
is thrown in its thread (thread_signal/2), Kind one of cpu(Limit),
memory(Limit), module_memory(Limit), memory_budget(Limit), posts(Limit),
log(Limit), wall(Limit) or idle(Limit) (a call parked too long); an
idle agent is removed by the monitor with the same warning and notice; a stack
overflow of the call is memory(Limit). The caller (agents.pl,
messages.pl) removes the agent from the node and calls bounds_stopped/3,
which prints one warning and tells the node the agent came from (the
source of its last transfer) with the request
bound_notice(Agent, Kind, Here): that node records it (agent_bound_report/3)
and prints it. A notice is checked for shape and size and can only ever
become such a record and a warning line. A thread that keeps running
after the signal (it was in foreign code, or a catch/3 of trusted code
took the signal) is signalled again every `dfrl_bounds_grace` seconds
(flag, 0.5), ten times at most; then the agent is purged and a warning
says the thread did not stop.

The monitor is one thread per process (`dfrl_bounds_monitor`, started on
the first bounded call). It wakes every `dfrl_bounds_period` seconds
(flag, 0.2) while calls run; when none does, it waits on its queue until
the first idle clock runs out (agent_idle_limit), at most 10 s; a
tick reads each running call's thread CPU time (about 0.6 us) and the
size of its agent's module.

The node's warnings about agents it stopped, refused or saw crash go
through bounds_warning/2: at most 20 per node and minute, then one line
says how many were suppressed.
*/

:- create_prolog_flag(dfrl_bounds_period, 0.2, [type(float), keep(true)]).
:- create_prolog_flag(dfrl_bounds_grace, 0.5, [type(float), keep(true)]).

:- dynamic
    call_/7,                    % Id, Node, Agent, Module, Thread, CPU0, Limits
    signalled_/4,               % Id, Kind, Time, Tries
    counters_/2,                % OutStream, ErrStream
    stream_role_/2,             % Stream, out|err
    default_target_/2,          % out|err, Stream
    arrived_/3,                 % Node, Agent, Source
    report_/4,                  % Node, Agent, Time, Report
    monitor_/2,                 % Thread, Queue
    monitor_idle_/0,            % the monitor waits for a call to start
    monitor_hot_/0,             % a node's agents hold over half its budget
    module_size_/3,             % Node, Agent, Bytes (last measured)
    slot_queue_/2,              % Node, Queue (max_running_agents tokens)
    reclaim_due_/1,             % Time: give freed memory back then
    reclaim_pass_/1,            % passes of the current reclaim so far
    tick_size_/2,               % Id, Bytes: module size this tick
    notice_/4,                  % Node, Agent, Kind, Source: to be sent
    notice_senders_/1,          % Count: senders draining notice_/4
    call_time_/4,               % Id, Start, Parked (s so far), ParkedSince|none
    active_/3.                  % Node, Agent, Time: an agent from a peer last ran

:- thread_local
    current_call_/4,            % Id, Node, Agent, Limits
    budget_/5,                  % Node, Agent, Limits, OutTarget, ErrTarget
    held_slot_/1,               % Slot: the run slot this thread's call holds
    swallowed_/1.               % Kind: the call ended after its signal

:- multifile
    node:platform_request/4,
    node:requires_authentication/1,
    node:node_stopping/1,
    agents:agent_changed/3.

max_notices_per_minute(60).
max_reports_kept(100).
max_signals(10).

		 /*******************************
		 *            A CALL		*
		 *******************************/

%!  bounds_call(+Node, +Agent, +Module, :Goal) is semidet.
%
%   Call Goal, a handler call of Agent (whose code and state live in
%   Module) on Node, within Node's per-call bounds: CPU time, stacks,
%   the size of Module, posts and output lines (see the module doc).
%   Succeeds or fails as Goal does. In a thread that already runs a
%   bounded call, Goal runs under that call's bounds.
%
%   @error '$dfrl_bound'(Kind) if the call went over a bound (then the
%   agent is to be removed and bounds_stopped/3 called), also if the
%   call caught the signal and ended normally.

bounds_call(_Node, _Agent, _Module, Goal) :-
    current_call_(_, _, _, _),
    !,
    call(Goal).
bounds_call(Node, Agent, Module, Goal) :-
    node_limits(Node, Limits),
    flag(dfrl_bounds_calls, Id, Id+1),
    setup_call_cleanup(
        hold_slot(Node, Agent),
        setup_call_cleanup(
            enter(Id, Node, Agent, Module, Limits, Saved),
            (   catch(Goal, E, call_error(E, Limits))
            ->  Result = true
            ;   Result = false
            ),
            leave(Id, Saved)),
        release_slot),
    (   retract(swallowed_(Kind))
    ->  throw('$dfrl_bound'(Kind))
    ;   true
    ),
    limit(Limits, module, MaxModule),
    module_size(Module, Size),
    (   over(Size, MaxModule)
    ->  throw('$dfrl_bound'(module_memory(MaxModule)))
    ;   true
    ),
    note_module_size(Node, Agent, Size),
    Result == true.

%   max_running_agents(N): a call takes one of N slots of its node (a
%   message queue holding N tokens) before it starts, and waits for one
%   when all are taken, at most agent_slot_wait(Sec) (node option, 60).
%   Waiting costs no CPU and is not counted in the call's bounds.
%   max_running_per_peer(P): a call of an agent that arrived from a peer
%   first takes one of that peer's P slots (a queue per node and peer),
%   so that one peer's calls never hold more than P of the N slots and
%   another peer's call finds one free. Both waits together take at
%   most agent_slot_wait. The slot held is kept thread-locally, so that
%   bounds_park/1 can give it back while the call waits.
hold_slot(Node, Agent) :-
    retractall(held_slot_(_)),
    take_slot(Node, Agent, Slot),
    assertz(held_slot_(Slot)).

release_slot :-
    (   retract(held_slot_(Slot))
    ->  give_slot(Slot)
    ;   true
    ).

take_slot(Node, Agent, Slot) :-
    node_option(Node, max_running_agents, Max),
    node_option(Node, agent_slot_wait, Wait),
    get_time(T0),
    Deadline is T0 + Wait,
    agent_peer(Node, Agent, Peer),
    node_option(Node, max_running_per_peer, PeerMax),
    (   ( Peer == local ; PeerMax == infinite )
    ->  PeerSlot = none
    ;   slot_queue(Node-Peer, PeerMax, PeerQueue),
        (   wait_token(PeerQueue, Deadline)
        ->  PeerSlot = PeerQueue
        ;   bounds_warning(Node, dfrl_bounds(no_slot(Node, Agent, PeerMax, Wait))),
            throw(error(resource_error(running_agents), context(_, peer_limit(PeerMax))))
        )
    ),
    (   Max == infinite
    ->  Slot = slot(none, PeerSlot)
    ;   slot_queue(Node, Max, Queue),
        (   wait_token(Queue, Deadline)
        ->  Slot = slot(Queue, PeerSlot)
        ;   give_slot(slot(none, PeerSlot)),
            bounds_warning(Node, dfrl_bounds(no_slot(Node, Agent, Max, Wait))),
            throw(error(resource_error(running_agents), context(_, limit(Max))))
        )
    ).

wait_token(Queue, Deadline) :-
    (   thread_get_message(Queue, slot, [timeout(0)])
    ->  true
    ;   stat_add(slot_waits, 1),
        get_time(Now),
        Left is max(0, Deadline - Now),
        thread_get_message(Queue, slot, [timeout(Left)])
    ).

give_slot(none).
give_slot(parked).
give_slot(slot(Queue, PeerQueue)) :-
    give_token(PeerQueue),
    give_token(Queue).

give_token(none) :- !.
give_token(Queue) :-
    catch(thread_send_message(Queue, slot), _, true).

%   The queue of the slots of Key (a node, or Node-Peer), made with Max
%   tokens on first use.
slot_queue(Key, Max, Queue) :-
    (   slot_queue_(Key, Q0)
    ->  Queue = Q0
    ;   with_mutex(dfrl_bounds_monitor,
                   (   slot_queue_(Key, Q0)
                   ->  Queue = Q0
                   ;   message_queue_create(Queue),
                       forall(between(1, Max, _), thread_send_message(Queue, slot)),
                       assertz(slot_queue_(Key, Queue))
                   ))
    ).

%   The peer an agent arrived from (agents.pl keeps it), `local` for an
%   agent made here, or one that is gone.
agent_peer(Node, Agent, Peer) :-
    (   agents:agent_property(Node, Agent, peer(P))
    ->  Peer = P
    ;   Peer = local
    ).

%!  bounds_park(:Goal) is semidet.
%
%   Call Goal (once) with the run slot of the current bounded call given
%   back: for node code that an agent's handler calls to wait (the dFRL
%   agent resting between rounds, waiting for a robot or for messages of
%   a tree round). Time parked is not counted in agent_wall_limit but
%   in agent_idle_limit (the most a call may stay parked, in all); CPU,
%   stacks and memory are counted as ever. After Goal the call takes a
%   slot again (waiting, parked, up to twice agent_slot_wait). Outside a bounded call, or
%   inside a parked one, it is call/1 under once/1. Not in the agent API:
%   an arriving agent's own code cannot park.
%
%   @error resource_error(running_agents) if no slot came back in
%   agent_slot_wait.

bounds_park(Goal) :-
    (   current_call_(Id, Node, Agent, _),
        held_slot_(Slot),
        Slot \== parked
    ->  park(Id, Slot),
        (   catch(Goal, E, true)
        ->  Result = true
        ;   Result = false
        ),
        (   nonvar(E),
            stops_call(E)
        ->  unpark(Id),
            throw(E)
        ;   true
        ),
        retractall(held_slot_(_)),              % waiting for a slot is parked
        catch(retake_slot(Node, Agent, Slot1), E1, ( unpark(Id), throw(E1) )),
        assertz(held_slot_(Slot1)),
        unpark(Id),
        (   nonvar(E) -> throw(E) ; Result == true )
    ;   once(Goal)
    ).

%   A parked call waits for a slot twice as long as a new one (two
%   agent_slot_wait): it has run already, and giving up costs its work.
retake_slot(Node, Agent, Slot) :-
    catch(take_slot(Node, Agent, Slot), error(resource_error(running_agents), _), fail),
    !.
retake_slot(Node, Agent, Slot) :-
    take_slot(Node, Agent, Slot).

%!  bounds_stop_ball(@Exception) is semidet.
%
%   Exception stops an agent's call (a bound, a purge, an abort): code
%   that catches errors of its own work on the agent's behalf (a request
%   to a peer) must throw it on, never turn it into an answer.

bounds_stop_ball(E) :-
    nonvar(E),
    stops_call(E).

stops_call('$dfrl_bound'(_)).
stops_call('$dfrl_purged').
stops_call('$aborted').
stops_call(unwind(_)).
stops_call(time_limit_exceeded).

park(Id, Slot) :-
    retractall(held_slot_(_)),
    assertz(held_slot_(parked)),
    give_slot(Slot),
    get_time(Now),
    with_mutex(dfrl_bounds,
               (   retract(call_time_(Id, Start, Parked, _))
               ->  assertz(call_time_(Id, Start, Parked, Now))
               ;   true
               )).

unpark(Id) :-
    get_time(Now),
    with_mutex(dfrl_bounds,
               (   retract(call_time_(Id, Start, Parked0, Since)),
                   number(Since)
               ->  Parked is Parked0 + Now - Since,
                   assertz(call_time_(Id, Start, Parked, none))
               ;   true
               )).

%   The last measured size of an agent still on its node.
note_module_size(Node, Agent, Size) :-
    with_mutex(dfrl_bounds,
               (   agents:agent_exists(Node, Agent)
               ->  retractall(module_size_(Node, Agent, _)),
                   assertz(module_size_(Node, Agent, Size))
               ;   true
               )).

%   SWI-Prolog's own stack limit is the memory bound.
call_error(error(resource_error(Stack), _), Limits) :-
    stack_resource(Stack),
    !,
    limit(Limits, stack, Max),
    throw('$dfrl_bound'(memory(Max))).
call_error(E, _) :-
    throw(E).

stack_resource(stack).
stack_resource(stack_overflow).
stack_resource(global_stack).
stack_resource(local_stack).
stack_resource(trail_stack).

node_limits(Node, limits(CPU, Stack, Module, Posts, Log, Wall, Idle)) :-
    node_option(Node, agent_cpu_limit, CPU),
    node_option(Node, agent_stack_limit, Stack),
    node_option(Node, agent_module_limit, Module),
    node_option(Node, agent_post_limit, Posts),
    node_option(Node, agent_log_limit, Log),
    node_option(Node, agent_wall_limit, Wall),
    node_option(Node, agent_idle_limit, Idle).

limit(limits(L, _, _, _, _, _, _), cpu, L).
limit(limits(_, L, _, _, _, _, _), stack, L).
limit(limits(_, _, L, _, _, _, _), module, L).
limit(limits(_, _, _, L, _, _, _), posts, L).
limit(limits(_, _, _, _, L, _, _), log, L).
limit(limits(_, _, _, _, _, L, _), wall, L).
limit(limits(_, _, _, _, _, _, L), idle, L).

over(Value, Limit) :-
    Limit \== infinite,
    Value > Limit.

enter(Id, Node, Agent, Module, Limits, saved(Stack0, Out0, Err0, Cur0)) :-
    thread_self(Me),
    thread_statistics(Me, cputime, CPU0),
    current_prolog_flag(stack_limit, Stack0),
    limit(Limits, stack, Stack),
    (   Stack == infinite
    ->  true
    ;   catch(set_prolog_flag(stack_limit, Stack), E,
              print_message(warning, E))
    ),
    once(stream_property(Out0, alias(user_output))),
    once(stream_property(Err0, alias(user_error))),
    current_output(Cur0),
    counters(Out, Err),
    target(out, Out0, OutTarget),
    target(err, Err0, ErrTarget),
    assertz(budget_(Node, Agent, Limits, OutTarget, ErrTarget)),
    set_stream(Out, alias(user_output)),
    set_stream(Err, alias(user_error)),
    set_output(Out),
    assertz(current_call_(Id, Node, Agent, Limits)),
    (   call_(_, _, _, _, _, _, _) -> true ; node_memory_note_idle ),
    get_time(Start),
    with_mutex(dfrl_bounds, assertz(call_time_(Id, Start, 0, none))),
    assertz(call_(Id, Node, Agent, Module, Me, CPU0, Limits)),
    monitor_wake.

%   The call's records go first, so that a signal arriving during the
%   clean-up finds no call to stop; its last output is counted still.
leave(Id, saved(Stack0, Out0, Err0, Cur0)) :-
    retractall(current_call_(Id, _, _, _)),
    (   retract(call_(Id, Node, Agent, _, Me, CPU0, _))
    ->  catch(( thread_statistics(Me, cputime, CPU1),
                Used is CPU1 - CPU0,
                stat_max(peak_cpu(Node), Used)
              ), _, true),
        note_active(Node, Agent)
    ;   true
    ),
    with_mutex(dfrl_bounds, retractall(call_time_(Id, _, _, _))),
    (   retract(signalled_(Id, Kind, _, _))
    ->  retractall(swallowed_(_)),
        assertz(swallowed_(Kind))           % a handler that took the signal
    ;   true
    ),
    counters(Out, Err),
    catch(flush_output(Out), _, true),
    catch(flush_output(Err), _, true),
    retractall(budget_(_, _, _, _, _)),
    set_stream(Out0, alias(user_output)),
    set_stream(Err0, alias(user_error)),
    set_output(Cur0),
    stat_add(calls, 1),
    catch(set_prolog_flag(stack_limit, Stack0), _, true).

%   The signal: stop the call Id if this thread still runs it.
stop_if_running(Id, Kind) :-
    (   current_call_(Id, _, _, _)
    ->  throw('$dfrl_bound'(Kind))
    ;   true
    ).

stop_call(Id, Thread, Kind) :-
    get_time(Now),
    with_mutex(dfrl_bounds,
               (   signalled_(Id, _, _, _)
               ->  New = false
               ;   assertz(signalled_(Id, Kind, Now, 1)),
                   New = true
               )),
    (   New == true
    ->  pool_signal(agents, Thread, agent_bounds:stop_if_running(Id, Kind))
    ;   true
    ).

%!  bounds_post is det.
%
%   Count one post sent by the agent whose bounded call runs in this
%   thread (no effect in other threads).
%
%   @error '$dfrl_bound'(posts(Limit)) if it sent more than its limit
%   in the current minute.

bounds_post :-
    (   current_call_(_, Node, Agent, Limits)
    ->  limit(Limits, posts, Max),
        window_take(posts(Node, Agent), Max, 1, Granted),
        (   Granted < 1
        ->  throw('$dfrl_bound'(posts(Max)))
        ;   true
        )
    ;   true
    ).

		 /*******************************
		 *            OUTPUT		*
		 *******************************/

%   The counting streams: one pair per process, never closed, because a
%   thread created during a bounded call (a pool worker, a connection)
%   inherits its creator's streams and keeps them. Output written through
%   them in a bounded call goes to the call's own user_output or
%   user_error until the agent's lines this minute reach its limit; then
%   it is dropped and the call stopped. Output of a thread that runs no
%   bounded call goes, uncounted, to the streams the process had when
%   the pair was made. A line is a newline, or 4096 characters without
%   one, or one flush of a partial line.
counters(Out, Err) :-
    (   counters_(Out0, Err0)
    ->  Out = Out0,
        Err = Err0
    ;   with_mutex(dfrl_bounds_monitor, make_counters),
        counters_(Out, Err)
    ).

make_counters :-
    (   counters_(_, _)
    ->  true
    ;   once(stream_property(Out0, alias(user_output))),
        once(stream_property(Err0, alias(user_error))),
        assertz(default_target_(out, Out0)),
        assertz(default_target_(err, Err0)),
        open_prolog_stream(agent_bounds, write, Out, []),
        open_prolog_stream(agent_bounds, write, Err, []),
        set_stream(Out, buffer(line)),
        set_stream(Err, buffer(line)),
        assertz(stream_role_(Out, out)),
        assertz(stream_role_(Err, err)),
        assertz(counters_(Out, Err))
    ).

%   Where a call's output goes: the thread's stream, unless that is a
%   counting stream it inherited.
target(Role, Stream, Target) :-
    (   stream_role_(Stream, _)
    ->  default_target_(Role, Target)
    ;   Target = Stream
    ).

%   Called by the stream layer in the writing thread.
stream_write(S, String) :-
    stream_role_(S, Role),
    (   budget_(Node, Agent, Limits, OutTarget, ErrTarget)
    ->  ( Role == out -> Target = OutTarget ; Target = ErrTarget ),
        limit(Limits, log, Limit),
        lines_counted(String, N),
        window_take(log(Node, Agent), Limit, N, Granted),
        (   Granted >= N
        ->  forward(Target, String)
        ;   Granted > 0
        ->  first_lines(String, Granted, Part),
            forward(Target, Part),
            log_over(Limit)
        ;   log_over(Limit)
        )
    ;   default_target_(Role, Target)
    ->  forward(Target, String)
    ;   true
    ).

stream_close(_).

forward(Target, String) :-
    catch(( write(Target, String), flush_output(Target) ), _, true).

log_over(Limit) :-
    (   current_call_(Id, _, _, _)
    ->  thread_self(Me),
        stop_call(Id, Me, log(Limit))
    ;   true
    ).

lines_counted(String, N) :-
    aggregate_all(count, sub_string(String, _, 1, _, "\n"), NL),
    string_length(String, Len),
    N is max(1, NL) + Len // 4096.

first_lines(String, N, Part) :-
    split_string(String, "\n", "", Lines),
    length(Keep, N),
    (   append(Keep, _, Lines)
    ->  atomic_list_concat(Keep, '\n', Part0),
        atom_concat(Part0, '\n', Part)
    ;   Part = String
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
    (   aggregate_all(min(T), ( reclaim_due_(T) ; idle_due(T) ), Due)
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
    catch(expire_idle, E3, print_message(warning, E3)),
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
           catch(check_call(Id, Node, Agent, Module, Thread, CPU0, Limits, Now),
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

check_call(Id, Node, Agent, _Module, Thread, _, _, Now) :-
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
        pool_signal(agents, Thread, agent_bounds:stop_if_running(Id, Kind))
    ;   Tries == Max
    ->  with_mutex(dfrl_bounds,
                   ( retract(signalled_(Id, Kind, Since, Tries)),
                     assertz(signalled_(Id, Kind, Now, gave_up)) )),
        bounds_warning(Node, dfrl_bounds(unstoppable(Node, Agent, Kind, Max))),
        catch(agents:agent_purge(Node, Agent), _, true)
    ;   true
    ).
check_call(Id, Node, _Agent, Module, Thread, CPU0, Limits, Now) :-
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
    ->  stop_call(Id, Thread, cpu(MaxCPU))
    ;   over(Held, MaxWall)
    ->  stat_add(wall_stops, 1),
        stop_call(Id, Thread, wall(MaxWall))
    ;   over(Parked, MaxParked)
    ->  stat_add(wall_stops, 1),
        stop_call(Id, Thread, idle(MaxParked))
    ;   MaxModule \== infinite,
        tick_module_size(Id, Module, Size),
        over(Size, MaxModule)
    ->  stop_call(Id, Thread, module_memory(MaxModule))
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
            stop_call(BigId, BigThread, memory_budget(Budget))
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
                stop_call(BigId, BigT, memory_budget(Budget))
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

%   The stacks a thread has allocated. In SWI-Prolog 9.0.4 the key
%   `stack` of thread_statistics/3 gives the stacks of the whole process,
%   the same for every thread (a memory bomb's stacks were charged to
%   every call running beside it, and the budget stopped an innocent
%   one); global, local and trail are the thread's own.
thread_stacks(Thread, Bytes) :-
    thread_statistics(Thread, global, G),
    thread_statistics(Thread, local, L),
    thread_statistics(Thread, trail, T),
    Bytes is G + L + T.

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

		 /*******************************
		 *      GIVING MEMORY BACK	*
		 *******************************/

%   After an agent that held much memory left (stopped, or a module of
%   16 MiB or more), its retracted clauses are reclaimed and the freed
%   heap given back to the OS (garbage_collect_clauses/0, trim_heap/0),
%   in the monitor thread, 0.3 s later (the stopped call's worker has
%   usually exited by then) and again 2, 6 and 15 s later: on a loaded
%   machine a worker can take seconds to exit, and while it has not,
%   clause garbage collection frees nothing (seen in a full test run
%   beside stress-ng --cpu 2: 8 stopped assert bombs left +591 MiB after
%   the 0.3 and 2 s passes). SWI-Prolog 9.0.4 frees erased
%   clauses over several passes (measured: 8 modules of 700,000 facts,
%   retractall/1, then garbage_collect_clauses/0 every 0.1 s: the
%   clause count fell over 3 to 4 passes; one pass and trim_heap gave
%   back 85 of 707 MB, passes until no progress and then trim_heap all
%   but 5 MB). So a reclaim repeats a pass every 0.1 s while the number
%   of clauses falls (at most 50 passes), then trims the heap.
reclaim_threshold(16777216).
max_reclaim_passes(50).

reclaim_after([0.3, 2.0, 6.0, 15.0]).

schedule_reclaim :-
    get_time(Now),
    reclaim_after(Delays),
    findall(T, ( member(D, Delays), T is Now + D ), Times),
    with_mutex(dfrl_bounds,
               forall(member(T, Times),
                      (   reclaim_due_(T0), abs(T0 - T) < 0.25
                      ->  true
                      ;   assertz(reclaim_due_(T))
                      ))),
    (   monitor_(_, Queue)
    ->  thread_send_message(Queue, wake)
    ;   with_mutex(dfrl_bounds_monitor, monitor_start(Queue)),
        thread_send_message(Queue, wake)
    ).

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

%   Bytes held by the clauses of Module's own predicates.
module_size(Module, Size) :-
    aggregate_all(sum(B),
                  ( current_predicate(_, Module:H),
                    \+ predicate_property(Module:H, imported_from(_)),
                    predicate_property(Module:H, size(B))
                  ),
                  Size).

%   An arriving agent's module, of Size bytes, against Node's
%   agent_module_limit.
check_module_size(Node, Size) :-
    node_option(Node, agent_module_limit, Max),
    (   over(Size, Max)
    ->  throw(error(resource_error(agent_memory),
                    context(_, too_large(Size, Max))))
    ;   true
    ).

		 /*******************************
		 *          IDLE AGENTS		*
		 *******************************/

%   agent_idle_limit(Sec): an agent that arrived from a peer (not one
%   made on this node, nor one a node of this process sent: agents.pl
%   knows them as peer `local`) is removed when it has not run for Sec
%   seconds: since it arrived or since its last handler call (its main
%   handler or a posted event) ended. The monitor wakes when the first
%   such agent is due. Only an agent that is `idle` is removed (under
%   the registry mutex): one running (a call parked with bounds_park/1
%   included), staged, in doubt or departing has its clock restarted.
%   It is removed as an agent over a bound is: one warning, and its
%   source gets bound_notice(Agent, idle(Sec), Here).

note_active(Node, Agent) :-
    get_time(Now),
    with_mutex(dfrl_bounds,
               (   retract(active_(Node, Agent, _))
               ->  assertz(active_(Node, Agent, Now))
               ;   true
               )).

%   When the first agent of any node falls due.
idle_due(Due) :-
    active_(Node, _, T),
    catch(node_option(Node, agent_idle_limit, Limit), _, fail),
    Limit \== infinite,
    Due is T + Limit.

expire_idle :-
    sweep_peer_queues,
    get_time(Now),
    findall(Node-Agent-Limit,
            ( active_(Node, Agent, T),
              catch(node_option(Node, agent_idle_limit, Limit), _, fail),
              over(Now - T, Limit)
            ),
            Due),
    forall(member(Node-Agent-Limit, Due),
           catch(expire(Node, Agent, Limit), E,
                 debug(dfrl(bounds), 'expire ~p: ~p', [Agent, E]))).

%   The slot queue of a peer that has no agent left on its node, and
%   whose tokens are all back, is destroyed (at most every 10 s): a
%   plaintext peer may claim a new address with every agent it sends.
:- dynamic queues_swept_/1.

sweep_peer_queues :-
    get_time(Now),
    (   queues_swept_(T), Now - T < 10
    ->  true
    ;   retractall(queues_swept_(_)),
        assertz(queues_swept_(Now)),
        with_mutex(dfrl_bounds_monitor,
                   findall(Q,
                           ( slot_queue_(Node-Peer, Q),
                             \+ agents:agent_property(Node, _, peer(Peer)),
                             catch(node_option(Node, max_running_per_peer, Max), _, fail),
                             integer(Max),
                             message_queue_property(Q, size(Max)),
                             retract(slot_queue_(Node-Peer, Q)) ),
                           Qs)),
        forall(member(Q, Qs), catch(message_queue_destroy(Q), _, true))
    ).

expire(Node, Agent, Limit) :-
    (   agents:agent_take_idle(Node, Agent)
    ->  stat_add(idle_expired, 1),
        Kind = idle(Limit),
        bounds_warning(Node, dfrl_bounds(stopped(Node, Agent, Kind))),
        (   arrived_(Node, Agent, Source)
        ->  notify(Node, Agent, Kind, Source)
        ;   true
        ),
        agents:agent_purge(Node, Agent)
    ;   agents:agent_exists(Node, Agent)
    ->  note_active(Node, Agent)
    ;   with_mutex(dfrl_bounds, retractall(active_(Node, Agent, _)))
    ).

		 /*******************************
		 *          ARRIVALS		*
		 *******************************/

%!  bounds_install(+Node, +Record, +Status, -Name) is det.
%
%   Install an arriving agent from Record (agent_install/5) within
%   Node's bounds: max_agents(N) is counted and the agent registered
%   under the registry mutex (simultaneous arrivals never make more than
%   N); then its module must be within agent_module_limit and fit in
%   what is left of agent_memory_budget (counted and noted under one
%   mutex). A refused agent is removed again and the refusal printed
%   (rate-limited) and raised, for the transfer's reply.
%
%   @error resource_error(agents)
%   @error resource_error(agent_memory)

bounds_install(Node, Record, Status, Name) :-
    bounds_install(Node, Record, Status, Name, local).

%!  bounds_install(+Node, +Record, +Status, -Name, +Peer) is det.
%
%   As bounds_install/4, for an agent that arrives from Peer
%   (bounds_peer/2; `local` for a node of this process): Node holds at
%   most max_agents_per_peer(N) agents of one peer (counted as max_agents
%   is), so that one peer cannot fill max_agents for the others.
%
%   @error resource_error(peer_agents)

bounds_install(Node, Record, Status, Name, Peer) :-
    node_option(Node, max_agents, Max),
    node_option(Node, max_agents_per_peer, MaxPeer),
    catch(agents:agent_install(Node, Record, Status, Name,
                               [max_agents(Max), peer(Peer), max_per_peer(MaxPeer)]),
          error(resource_error(What), C),
          ( ( What == peer_agents -> Limit = MaxPeer ; Limit = Max ),
            bounds_warning(Node, dfrl_bounds(refused(Node, What, Limit))),
            throw(error(resource_error(What), C)) )),
    agents:agent_module(Node, Name, Module),
    catch(admit_memory(Node, Name, Module), E,
          ( agents:agent_remove(Node, Name), throw(E) )).

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

%!  bounds_admit(+Node, +Mode, +Agents) is det.
%
%   Admit an arriving agent (Mode `move` or `clone`) on Node, which holds
%   Agents agents: at most max_agents(N), and at most clone_limit(N)
%   clones a minute. A refusal is printed (rate-limited) and raised, for
%   the transfer's reply.
%
%   @error resource_error(agents)
%   @error resource_error(clones)

bounds_admit(Node, Mode, Agents) :-
    node_option(Node, max_agents, Max),
    (   over(Agents + 1, Max)
    ->  refuse(Node, agents, Max)
    ;   Mode == clone
    ->  node_option(Node, clone_limit, Clones),
        window_take(clones(Node), Clones, 1, Granted),
        (   Granted < 1
        ->  refuse(Node, clones, Clones)
        ;   true
        )
    ;   true
    ).

refuse(Node, What, Max) :-
    bounds_warning(Node, dfrl_bounds(refused(Node, What, Max))),
    throw(error(resource_error(What), context(_, limit(Max)))).

%!  bounds_arrived(+Node, +Agent, +Source) is det.
%
%   Agent arrived on Node from the node at address Source: that node is
%   told if Agent is stopped here.

bounds_arrived(Node, Agent, Source) :-
    retractall(arrived_(Node, Agent, _)),
    assertz(arrived_(Node, Agent, Source)).

%!  bounds_arrived(+Node, +Agent, +Source, +Peer) is det.
%
%   As bounds_arrived/3, Agent having come from Peer (bounds_peer/2):
%   unless Peer is `local`, its idle time counts from now
%   (agent_idle_limit).

bounds_arrived(Node, Agent, Source, Peer) :-
    bounds_arrived(Node, Agent, Source),
    (   Peer == local
    ->  true
    ;   get_time(Now),
        with_mutex(dfrl_bounds,
                   ( retractall(active_(Node, Agent, _)),
                     assertz(active_(Node, Agent, Now)) ))
    ).

%!  bounds_peer(+Ctx, -Peer) is det.
%
%   Peer is what the connection Ctx proves of its peer: tls(Name), the
%   common name of its verified certificate, on a TLS connection; else
%   its IP address as tcp_accept/3 gave it (e.g. ip(127,0,0,1)), without
%   the port.

bounds_peer(Ctx, Peer) :-
    (   ctx_peer_name(Ctx, Name)
    ->  Peer = tls(Name)
    ;   ctx_peer(Ctx, Address),
        peer_host(Address, Host)
    ->  Peer = Host
    ;   Peer = unknown
    ).

peer_host(Host:_, Host) :- !.
peer_host(Host, Host) :- ground(Host).

%!  bounds_peer(+Ctx, +Claim, -Peer) is det.
%
%   Peer identifies the peer of Ctx for the per-peer bounds: tls(Name)
%   on a TLS connection (Claim is not used: the certificate says who it
%   is); on plaintext claim(IP, Address), its IP address and the node
%   address it claims (Claim: the source address of a transfer, the link
%   of a post; Host:Port or (Host,Port), else `none`). A plaintext peer
%   proves nothing but its IP address and a token, so every process on
%   one host (all robots of a loopback federation) has one IP: the
%   claimed address tells them apart, and is believed. A token holder
%   that claims many addresses gets many shares: the node-wide bounds
%   (max_agents, max_running_agents, the pool of posts) and the wall
%   and idle bounds still hold it; TLS gives names it cannot forge.

bounds_peer(Ctx, Claim, Peer) :-
    bounds_peer(Ctx, Peer0),
    (   Peer0 = tls(_)
    ->  Peer = Peer0
    ;   claimed_address(Claim, Address)
    ->  Peer = claim(Peer0, Address)
    ;   Peer = claim(Peer0, none)
    ).

claimed_address(Host:Port, Host:Port) :-
    short_atomic(Host),
    integer(Port),
    !.
claimed_address((Host, Port), Host:Port) :-
    short_atomic(Host),
    integer(Port).

%   At most 1024 peers of a node have a post window at a time.
max_post_peers(1024).

post_key(Node, Peer0, Peer) :-
    (   Peer0 = claim(IP, _),
        \+ window_live(peer_posts(Node, Peer0)),
        max_post_peers(Max),
        windows_prune(peer_posts(Node, _), Live),
        Live >= Max
    ->  Peer = claim(IP, many)
    ;   Peer = Peer0
    ).

short_atomic(X) :-
    atomic(X),
    \+ string(X),
    atom_length(X, L),
    L =< 255.
%!  bounds_peer_post(+Ctx, +Link) is det.
%
%   Count one post delivered from the peer of Ctx (bounds_peer/3, Link
%   the link the post carries, the sender's address by convention)
%   against the node's peer_post_limit(N) (per peer and minute). The
%   windows are kept for at most 1024 peers of a node at a time (those
%   of the last minute); a post from a peer beyond them counts for
%   claim(IP, many), shared by all such peers of its IP address.
%
%   @error resource_error(posts) if the peer delivered N posts this
%   minute already; such refusals are counted (bounds_statistics/1,
%   `refused_posts`) and a warning printed (rate-limited).

bounds_peer_post(Ctx, Link) :-
    ctx_node(Ctx, Node),
    node_option(Node, peer_post_limit, Max),
    (   Max == infinite
    ->  true
    ;   bounds_peer(Ctx, Link, Peer0),
        post_key(Node, Peer0, Peer),
        window_take(peer_posts(Node, Peer), Max, 1, Granted),
        (   Granted < 1
        ->  stat_add(refused_posts, 1),
            stat_add(refused_posts(Node), 1),
            bounds_warning(Node, dfrl_bounds(refused_posts(Node, Peer, Max))),
            throw(error(resource_error(posts), context(_, peer_limit(Max))))
        ;   true
        )
    ).

agents:agent_changed(removed, Node, Agent) :-
    retractall(arrived_(Node, Agent, _)),
    with_mutex(dfrl_bounds, retractall(active_(Node, Agent, _))),
    (   with_mutex(dfrl_bounds, retract(module_size_(Node, Agent, Size))),
        reclaim_threshold(Big),
        Size >= Big
    ->  schedule_reclaim
    ;   true
    ),
    window_forget(log(Node, Agent)),
    window_forget(posts(Node, Agent)).

node:node_stopping(Node) :-
    retractall(arrived_(Node, _, _)),
    with_mutex(dfrl_bound_notices, retractall(notice_(Node, _, _, _))),
    retractall(report_(Node, _, _, _)),
    with_mutex(dfrl_bounds, retractall(module_size_(Node, _, _))),
    with_mutex(dfrl_bounds, retractall(active_(Node, _, _))),
    with_mutex(dfrl_bounds_monitor,
               findall(Queue,
                       ( slot_queue_(Key, Queue),
                         ( Key == Node ; Key = Node-_ ),
                         retract(slot_queue_(Key, Queue)) ),
                       Queues)),
    forall(member(Queue, Queues),
           catch(message_queue_destroy(Queue), _, true)),
    windows_forget_node(Node).

		 /*******************************
		 *      STOPPED: WARN, TELL	*
		 *******************************/

%!  bounds_stopped(+Node, +Agent, +Kind) is det.
%
%   Agent was stopped on Node for going over bound Kind (its handler
%   thread calls this, after '$dfrl_bound'(Kind), before removing the
%   agent): print one warning, tell the node it came from, and let the
%   worker thread exit after its job (a thread that held large stacks
%   gives them back only when it ends).

bounds_stopped(Node, Agent, Kind) :-
    stat_add(stopped, 1),
    bounds_warning(Node, dfrl_bounds(stopped(Node, Agent, Kind))),
    (   arrived_(Node, Agent, Source)
    ->  notify(Node, Agent, Kind, Source)
    ;   true
    ),
    schedule_reclaim,
    pool_retire.

%   Notices wait in a list (at most 60 per node and minute are taken,
%   so it stays short) that at most two senders of the pool
%   dfrl_bound_notices drain. A notice is never dropped because the
%   senders are busy: when eight agents are stopped at once, the sender
%   already running takes the ones it finds (with two pool workers and
%   no list, the third notice was refused by the pool and lost). The
%   count of running senders and the list change under one mutex, so a
%   sender cannot leave while a notice it did not see waits.
notify(Node, Agent, Kind, Source) :-
    max_notices_per_minute(Max),
    window_take(notices(Node), Max, 1, Granted),
    (   Granted =:= 1
    ->  with_mutex(dfrl_bound_notices,
                   ( assertz(notice_(Node, Agent, Kind, Source)),
                     (   notice_senders_(N), N >= 2
                     ->  Start = false
                     ;   change_senders(1),
                         Start = true
                     ) )),
        (   Start == true
        ->  catch(pool_run(dfrl_bound_notices, send_notices, [max(8)]), E,
                  ( with_mutex(dfrl_bound_notices, change_senders(-1)),
                    debug(dfrl(bounds), 'notice sender not started: ~p', [E]) ))
        ;   true
        )
    ;   true
    ).

send_notices :-
    with_mutex(dfrl_bound_notices,
               (   retract(notice_(Node, Agent, Kind, Source))
               ->  Next = notice(Node, Agent, Kind, Source)
               ;   change_senders(-1),
                   Next = none
               )),
    (   Next = notice(Node, Agent, Kind, Source)
    ->  catch(send_notice(Node, Agent, Kind, Source), E,
              debug(dfrl(bounds), 'notice of ~p: ~p', [Agent, E])),
        send_notices
    ;   true
    ).

change_senders(Delta) :-
    (   retract(notice_senders_(N0)) -> true ; N0 = 0 ),
    N is N0 + Delta,
    assertz(notice_senders_(N)).

send_notice(Node, Agent, Kind, Source) :-
    node_property(Node, address(Here)),
    (   node_for_address(Source, Local)
    ->  record_report(Local, Agent, Kind, Here, local)
    ;   node_property(Node, tokens(Tokens)),
        node_option(Node, connect_timeout, CT),
        catch(with_node(Node,
                        transport_request(Source, bound_notice(Agent, Kind, Here), _,
                                          [ tokens(Tokens), connect_timeout(CT),
                                            reply_timeout(CT) ])),
              E, debug(dfrl(bounds), 'notice to ~p: ~p', [Source, E]))
    ).

node:requires_authentication(bound_notice(_, _, _)).

node:platform_request(bound_notice(Agent, Kind, From), Ctx, ok(noted), true) :-
    ctx_node(Ctx, Node),
    (   valid_notice(Agent, Kind, From)
    ->  true
    ;   throw(error(domain_error(bound_notice, bound_notice/3), _))
    ),
    (   ctx_peer(Ctx, Peer) -> true ; Peer = unknown ),
    record_report(Node, Agent, Kind, From, Peer).

%   A notice holds an agent name, a bound and an address, of bounded
%   size; nothing else is accepted.
valid_notice(Agent, Kind, Host:Port) :-
    atom(Agent), atom_length(Agent, AL), AL =< 256,
    compound(Kind), compound_name_arity(Kind, K, 1),
    memberchk(K, [cpu, memory, module_memory, memory_budget, posts, log,
                  text_size, integer_size, wall, idle]),
    arg(1, Kind, Limit),
    ( number(Limit) ; Limit == infinite ),
    atomic(Host), \+ number(Host), atom_length(Host, HL), HL =< 256,
    integer(Port), between(0, 65535, Port).

record_report(Node, Agent, Kind, From, Peer) :-
    get_time(Now),
    Report = bound(Kind, From, Peer),
    with_mutex(dfrl_bounds,
               ( assertz(report_(Node, Agent, Now, Report)),
                 prune_reports(Node) )),
    bounds_warning(Node, dfrl_bounds(report(Node, Agent, Kind, From))).

prune_reports(Node) :-
    max_reports_kept(Max),
    aggregate_all(count, report_(Node, _, _, _), N),
    (   N > Max,
        retract(report_(Node, _, _, _))
    ->  prune_reports(Node)
    ;   true
    ).

%!  agent_bound_report(?Node, ?Agent, ?Report) is nondet.
%
%   Node was told that its Agent was stopped elsewhere for going over a
%   bound. Report is bound(Kind, From, Peer, Time): Kind as in
%   '$dfrl_bound'(Kind), From the address the stopping node gave, Peer
%   the connection's peer (`local` for a node of this process), Time
%   when it was told. The last 100 per node are kept.

agent_bound_report(Node, Agent, bound(Kind, From, Peer, Time)) :-
    report_(Node, Agent, Time, bound(Kind, From, Peer)).
