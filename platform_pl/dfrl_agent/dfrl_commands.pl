:- module(dfrl_commands,
          [ queue_command/3,            % +Node, +Agent, +Command
            dfrl_pending/3,             % ?Node, ?Agent, ?Command
            take_commands/2,            % +Agent, -Commands
            take_stop/1,                % +Agent
            apply_command/5             % +Carried, +Command, +Acc0, -Acc, -Status
          ]).
:- use_module('../tartarus', [current_node/1]).
:- use_module(dfrl_aggregation, [dfrl_method/1, method_applies_to/2]).
:- autoload(library(lists), [append/3, memberchk/2]).

/** <module> The control commands queued for a dFRL agent

The queue behind the platform event dfrl_control/4 (dfrl_agent.pl): a
command posted to a node waits here, per node and agent, until the
agent takes it at its next round start (dfrl_rounds.pl) and applies it
to its plan, method and stop flag with apply_command/5. This module
owns the queue; no other module asserts into it.
*/

:- dynamic
    pending/3.                  % Node, Agent, Command (queued control)

%!  queue_command(+Node, +Agent, +Command) is det.
%
%   Queue Command for Agent on Node, after those queued before.

queue_command(Node, Agent, Command) :-
    assertz(pending(Node, Agent, Command)).

%!  dfrl_pending(?Node, ?Agent, ?Command) is nondet.
%
%   Command is queued on Node for Agent and not yet taken.

dfrl_pending(Node, Agent, Command) :-
    pending(Node, Agent, Command).

%!  take_commands(+Agent, -Commands) is det.
%
%   Commands are those queued for Agent on the current node, in order;
%   they are taken off the queue.

take_commands(Agent, Commands) :-
    current_node(Node),
    findall(C, retract(pending(Node, Agent, C)), Commands).

%!  take_stop(+Agent) is semidet.
%
%   A stop command is queued for Agent on the current node: take it
%   (and any other stop queued).

take_stop(Agent) :-
    current_node(Node),
    retract(pending(Node, Agent, stop)),
    !,
    retractall(pending(Node, Agent, stop)).

%!  apply_command(+Carried, +Command, +Plan0-Method0-Stop0,
%!                -Plan-Method-Stop, -Status) is det.
%
%   Apply Command to an agent that carries Carried: join(Stop) adds a
%   stop to the plan's itinerary, method(Name) switches the method (if
%   known here and it applies to Carried), stop sets the stop flag.
%   Status is `applied` or ignored(Why).

apply_command(_, join(Stop), plan(I0, R, Re, L, T)-M-S, Plan-M-S, Status) :-
    Stop = stop(H, P, Robot), atomic(H), integer(P), atom(Robot),
    !,
    (   memberchk(Stop, I0)
    ->  Plan = plan(I0, R, Re, L, T),
        Status = ignored("the stop is already in the itinerary")
    ;   append(I0, [Stop], I),
        Plan = plan(I, R, Re, L, T),
        Status = applied
    ).
apply_command(Carried, method(New), P-Old-S, P-M-S, Status) :-
    atom(New),
    !,
    (   \+ dfrl_method(New)
    ->  M = Old,
        format(string(Why), "unknown method ~q on this node; keeps ~q", [New, Old]),
        Status = ignored(Why)
    ;   \+ method_applies_to(New, Carried)
    ->  M = Old,
        format(string(Why), "method ~q does not apply to ~w; keeps ~q",
               [New, Carried, Old]),
        Status = ignored(Why)
    ;   M = New,
        Status = applied
    ).
apply_command(_, stop, P-M-_, P-M-true, applied) :-
    !.
apply_command(_, _, X, X, ignored("not a control command")).
