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
:- use_module(node, [node_option/3]).
:- use_module(worker_pool, [pool_retire/0]).
:- use_module(bounds_ledger,
              [ window_take/4, window_forget/1, windows_forget_node/1, bounds_warning/2,
                stat_add/2, bounds_statistics/1 ]).
:- use_module(bounds_limits, [node_limits/2, limit/3, over/2, module_size/2]).
:- use_module(bounds_slots, [slot_hold/2, slot_release/0, slot_park/0, slot_unpark/2]).
:- use_module(bounds_output, [output_count_enter/5, output_count_leave/1]).
:- use_module(bounds_monitor,
              [ monitor_call_started/7, monitor_call_ended/2, monitor_park/1,
                monitor_unpark/1, monitor_stop_call/3, monitor_reclaim/0,
                note_module_size/3, admit_memory/3, bounds_node_memory/2 ]).
:- use_module(bounds_idle, [idle_clock_start/2]).
:- use_module(bounds_peers, [bounds_peer/2, bounds_peer/3, bounds_peer_post/2]).
:- use_module(bounds_notices,
              [bounds_arrived/3, bounds_notify_source/3, agent_bound_report/3]).

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

The node's warnings about agents it stopped, refused or saw crash go
through bounds_warning/2: at most 20 per node and minute, then one line
says how many were suppressed.

The parts: bounds_limits.pl (the limits record, module sizes),
bounds_slots.pl (run slots), bounds_output.pl (counted output),
bounds_monitor.pl (the running calls and the thread that checks them),
bounds_idle.pl (idle agents), bounds_reclaim.pl (memory given back),
bounds_peers.pl (who a peer is), bounds_notices.pl (telling the source),
bounds_ledger.pl (windows, counters, warnings).
*/

:- thread_local
    current_call_/4,            % Id, Node, Agent, Limits
    swallowed_/1.               % Kind: the call ended after its signal

:- multifile
    node:node_stopping/1,
    agents:agent_changed/3.

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
        slot_hold(Node, Agent),
        setup_call_cleanup(
            enter(Id, Node, Agent, Module, Limits, Saved),
            (   catch(Goal, E, call_error(E, Limits))
            ->  Result = true
            ;   Result = false
            ),
            leave(Id, Saved)),
        slot_release),
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
        slot_park
    ->  monitor_park(Id),
        (   catch(Goal, E, true)
        ->  Result = true
        ;   Result = false
        ),
        (   nonvar(E),
            stops_call(E)
        ->  monitor_unpark(Id),
            throw(E)
        ;   true
        ),
        catch(slot_unpark(Node, Agent), E1, ( monitor_unpark(Id), throw(E1) )),
        monitor_unpark(Id),
        (   nonvar(E) -> throw(E) ; Result == true )
    ;   once(Goal)
    ).

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

enter(Id, Node, Agent, Module, Limits, saved(Stack0, Streams)) :-
    thread_self(Me),
    thread_statistics(Me, cputime, CPU0),
    current_prolog_flag(stack_limit, Stack0),
    limit(Limits, stack, Stack),
    (   Stack == infinite
    ->  true
    ;   catch(set_prolog_flag(stack_limit, Stack), E,
              print_message(warning, E))
    ),
    limit(Limits, log, Log),
    output_count_enter(Node, Agent, Log, log_over, Streams),
    assertz(current_call_(Id, Node, Agent, Limits)),
    monitor_call_started(Id, Node, Agent, Module, Me, CPU0, Limits).

%   The call's records go first, so that a signal arriving during the
%   clean-up finds no call to stop; its last output is counted still.
leave(Id, saved(Stack0, Streams)) :-
    monitor_call_ended(Id, Signalled),
    retractall(current_call_(Id, _, _, _)),
    (   Signalled == none
    ->  true
    ;   retractall(swallowed_(_)),
        assertz(swallowed_(Signalled))      % a handler that took the signal
    ),
    output_count_leave(Streams),
    stat_add(calls, 1),
    catch(set_prolog_flag(stack_limit, Stack0), _, true).

%   The agent's output went over its lines this minute.
log_over(Limit) :-
    (   current_call_(Id, _, _, _)
    ->  thread_self(Me),
        monitor_stop_call(Id, Me, log(Limit))
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

%!  bounds_arrived(+Node, +Agent, +Source, +Peer) is det.
%
%   As bounds_arrived/3, Agent having come from Peer (bounds_peer/2):
%   unless Peer is `local`, its idle time counts from now
%   (agent_idle_limit).

bounds_arrived(Node, Agent, Source, Peer) :-
    bounds_arrived(Node, Agent, Source),
    (   Peer == local
    ->  true
    ;   idle_clock_start(Node, Agent)
    ).

agents:agent_changed(removed, Node, Agent) :-
    window_forget(log(Node, Agent)),
    window_forget(posts(Node, Agent)).

node:node_stopping(Node) :-
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
    bounds_notify_source(Node, Agent, Kind),
    monitor_reclaim,
    pool_retire.
