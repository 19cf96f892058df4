:- module(agent_execution,
          [ agent_execute/4,            % +Node, +Name, +Link, +Event
            current_agent/1,            % -Name
            agent_purge/2,              % +Node, +Name
            agent_remove/2              % +Node, +Name
          ]).
:- use_module(node, [node_set_current/1, node_clear_current/0]).
:- use_module(worker_pool, [pool_run/3, pool_signal/3]).
:- use_module(hop_probe, [hop_probe/1]).      % compiled away unless benchmarking
:- use_module(agent_bounds, [bounds_call/4, bounds_stopped/3, bounds_warning/2]).
:- use_module(agent_registry,
              [ with_agents_locked/1, agent_notify/3, agent_module/3, agent_exists/2,
                agent_must_exist/2, agent_property/3, agent_set_status/3,
                agent_unregister/2 ]).
:- use_module(agent_code, [empty_module/1]).
:- autoload(library(error), [permission_error/3]).
:- autoload(library(debug), [debug/3]).

/** <module> Running an agent: its handler in a pool worker, and its end

agent_execute/4 hands an agent to a worker of the pool `agents`
(worker_pool.pl), which calls its handler as Handler(Name, Link, Event)
in the agent's module, inside the bounds of agent_bounds.pl, with the
node as the thread's current node and the agent as its current_agent/1.
When the handler returns the agent stays on the node, idle, until it is
executed again, moved or purged. A status in the registry says where an
agent is in this: idle, starting, running(Thread).

Purging an agent signals the worker that runs it (if any) and forgets
it: its module is emptied (agent_code.pl) and its records are dropped
(agent_registry.pl). An agent over one of its bounds is purged too, and
its sender told why. A node that stops forgets its agents (hook
node:node_stopping/1).
*/

:- thread_local
    current_agent_tl/1.

:- multifile
    node:node_stopping/1.

%   A stopping node forgets its agents without telling the custody hook:
%   stopping a node is not purging its agents, a node restarted with its
%   store recovers them.
node:node_stopping(Node) :-
    forall(agent_exists(Node, Name),
           catch(purge(Node, Name, quiet), _, true)).

%!  agent_execute(+Node, +Name, +Link, +Event) is det.
%
%   Start agent Name in a new thread: its handler is called as
%   Handler(Name, Link, Event) in the agent's module.
%
%   @error existence_error(agent, Name)
%   @error permission_error(execute, agent, Name) if it is already
%   running or in transit.

agent_execute(Node, Name, Link, Event) :-
    agent_must_exist(Node, Name),
    with_agents_locked(start_thread(Node, Name, Link, Event)).

start_thread(Node, Name, Link, Event) :-
    agent_property(Node, Name, status(Status)),
    (   Status == idle
    ->  true
    ;   Status = running(Tid), thread_self(Tid)
    ->  true                    % re-executed from its own handler
    ;   permission_error(execute, agent, Name)
    ),
    agent_set_status(Node, Name, starting),
    pool_run(agents, agent_run(Node, Name, Link, Event), []).

agent_run(Node, Name, Link, Event) :-
    hop_probe(run_started),
    thread_self(Me),
    with_agents_locked(
        (   agent_property(Node, Name, status(starting))
        ->  agent_set_status(Node, Name, running(Me)),
            Run = true
        ;   Run = false                 % purged or moved before it started
        )),
    (   Run == true
    ->  catch(agent_notify(run(run), Node, Name), E0,
              print_message(warning, E0)),
        %   a purge signalled while the handler's own catch is not yet
        %   (or no longer) active ends the run here, quietly: the agent
        %   is gone, as when the signal lands inside the handler
        catch(setup_call_cleanup(
                  enter_agent(Node, Name),
                  run_agent(Node, Name, Link, Event),
                  leave_agent),
              '$dfrl_purged', true),
        with_agents_locked(
            (   agent_property(Node, Name, status(running(Me)))
            ->  agent_set_status(Node, Name, idle),
                Rested = true
            ;   Rested = false
            )),
        (   Rested == true
        ->  catch(agent_notify(run(idle), Node, Name), E,
                  print_message(warning, E))
        ;   true
        )
    ;   true
    ).

%   A node stopped since the agent was started is no error here: the
%   agent then runs with the default node, and is purged by the stop.
enter_agent(Node, Name) :-
    catch(node_set_current(Node), error(existence_error(platform, _), _), true),
    assertz(current_agent_tl(Name)).

leave_agent :-
    retractall(current_agent_tl(_)),
    node_clear_current.

run_agent(Node, Name, Link, Event) :-
    (   agent_property(Node, Name, handler(Handler))
    ->  agent_module(Node, Name, M),
        Goal =.. [Handler, Name, Link, Event],
        hop_probe(bounds_entering),
        catch(bounds_call(Node, Name, M, run_handler(Node, Name, M:Goal)), E,
              handler_error(Node, Name, E))
    ;   true
    ).

run_handler(Node, Name, Goal) :-
    hop_probe(handler_called),
    (   call(Goal)
    ->  true
    ;   debug(dfrl(agent), 'Handler of ~p on ~w failed', [Name, Node])
    ).

%   Signalled to the worker running agent Name when it is purged; the
%   worker may have moved on to another job, then nothing happens.
purge_if_running(Name) :-
    (   current_agent_tl(Name)
    ->  throw('$dfrl_purged')
    ;   true
    ).

%   An agent over one of its bounds (agent_bounds.pl) is removed, not
%   left idle; its sender is told why.
handler_error(_, _, '$dfrl_purged') :- !.
handler_error(Node, Name, '$dfrl_bound'(Kind)) :-
    !,
    bounds_stopped(Node, Name, Kind),
    (   agent_exists(Node, Name)
    ->  catch(purge(Node, Name, notify), E,
              print_message(warning, E))
    ;   true
    ).
handler_error(Node, Name, E) :-
    bounds_warning(Node, dfrl(agent_crashed(Node, Name, E))).

%!  current_agent(-Name) is semidet.
%
%   Name is the agent whose handler runs in the calling thread.

current_agent(Name) :-
    current_agent_tl(Name).

%!  agent_purge(+Node, +Name) is det.
%
%   Stop agent Name (if running, its thread is interrupted) and forget
%   it with its code and payload.
%
%   @error existence_error(agent, Name)

agent_purge(Node, Name) :-
    purge(Node, Name, notify).

purge(Node, Name, Notify) :-
    agent_must_exist(Node, Name),
    (   agent_property(Node, Name, status(running(Tid))),
        \+ thread_self(Tid)
    ->  pool_signal(agents, Tid, agent_execution:purge_if_running(Name))
    ;   true
    ),
    forget(Node, Name),
    (   Notify == notify
    ->  agent_notify(removed, Node, Name)
    ;   true
    ).

%!  agent_remove(+Node, +Name) is det.
%
%   Forget agent Name and its code on Node (without touching a thread).

agent_remove(Node, Name) :-
    forget(Node, Name),
    agent_notify(removed, Node, Name).

forget(Node, Name) :-
    agent_module(Node, Name, M),
    empty_module(M),
    agent_unregister(Node, Name).
