:- module(bounds_idle,
          [ idle_clock_start/2,         % +Node, +Agent
            idle_note_active/2,         % +Node, +Agent
            idle_due/1,                 % -Time
            idle_expire/0
          ]).
%   Eager imports (not autoload/2): see node_connection.pl.
:- use_module(library(lists), [member/2]).
:- use_module(library(debug), [debug/3]).
:- use_module(node, [node_option/3]).
:- use_module(bounds_ledger, [bounds_warning/2, stat_add/2]).
:- use_module(bounds_notices, [bounds_notify_source/3]).

/** <module> Agents from peers that stay idle too long

agent_idle_limit(Sec): an agent that arrived from a peer (not one
made on this node, nor one a node of this process sent: agents.pl
knows them as peer `local`) is removed when it has not run for Sec
seconds: since it arrived or since its last handler call (its main
handler or a posted event) ended. The monitor wakes when the first
such agent is due. Only an agent that is `idle` is removed (under
the registry mutex): one running (a call parked with bounds_park/1
included), staged, in doubt or departing has its clock restarted.
It is removed as an agent over a bound is: one warning, and its
source gets bound_notice(Agent, idle(Sec), Here).

This module keeps the agents' idle clocks; the monitor thread of
agent_bounds.pl (bounds_monitor.pl) calls idle_expire/0 when the first
is due.
*/

:- dynamic
    active_/3.                  % Node, Agent, Time: an agent from a peer last ran

:- multifile
    node:node_stopping/1,
    agents:agent_changed/3.

%!  idle_clock_start(+Node, +Agent) is det.
%
%   Agent arrived on Node from a peer: its idle time counts from now.

idle_clock_start(Node, Agent) :-
    get_time(Now),
    with_mutex(dfrl_bounds,
               ( retractall(active_(Node, Agent, _)),
                 assertz(active_(Node, Agent, Now)) )).

%!  idle_note_active(+Node, +Agent) is det.
%
%   A handler call of Agent on Node ended: its idle clock restarts (if
%   it has one).

idle_note_active(Node, Agent) :-
    get_time(Now),
    with_mutex(dfrl_bounds,
               (   retract(active_(Node, Agent, _))
               ->  assertz(active_(Node, Agent, Now))
               ;   true
               )).

%!  idle_due(-Time) is nondet.
%
%   Time when an agent of some node falls due (one solution per agent
%   with an idle clock and a finite agent_idle_limit).

idle_due(Due) :-
    active_(Node, _, T),
    catch(node_option(Node, agent_idle_limit, Limit), _, fail),
    Limit \== infinite,
    Due is T + Limit.

%!  idle_expire is det.
%
%   Remove every agent whose idle clock ran out.

idle_expire :-
    get_time(Now),
    findall(Node-Agent-Limit,
            ( active_(Node, Agent, T),
              catch(node_option(Node, agent_idle_limit, Limit), _, fail),
              Limit \== infinite,
              Now - T > Limit
            ),
            Due),
    forall(member(Node-Agent-Limit, Due),
           catch(expire(Node, Agent, Limit), E,
                 debug(dfrl(bounds), 'expire ~p: ~p', [Agent, E]))).

expire(Node, Agent, Limit) :-
    (   agents:agent_take_idle(Node, Agent)
    ->  stat_add(idle_expired, 1),
        Kind = idle(Limit),
        bounds_warning(Node, dfrl_bounds(stopped(Node, Agent, Kind))),
        bounds_notify_source(Node, Agent, Kind),
        agents:agent_purge(Node, Agent)
    ;   agents:agent_exists(Node, Agent)
    ->  idle_note_active(Node, Agent)
    ;   with_mutex(dfrl_bounds, retractall(active_(Node, Agent, _)))
    ).

agents:agent_changed(removed, Node, Agent) :-
    with_mutex(dfrl_bounds, retractall(active_(Node, Agent, _))).

node:node_stopping(Node) :-
    with_mutex(dfrl_bounds, retractall(active_(Node, _, _))).
