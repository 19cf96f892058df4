:- module(agent_registry,
          [ with_agents_locked/1,       % :Goal
            agent_notify/3,             % +Event, +Node, +Name
            agent_module/3,             % +Node, +Name, -Module
            agent_exists/2,             % ?Node, ?Name
            agent_must_exist/2,         % +Node, +Name
            agent_property/3,           % ?Node, ?Name, ?Property
            agent_list/2,               % +Node, -Agents
            agent_registered/3,         % +Node, +Name, -Registered
            agent_status/3,             % +Node, +Name, -Status
            agent_set_status/3,         % +Node, +Name, +Status
            agent_take_idle/2,          % +Node, +Name
            agent_fresh_name/3,         % +Node, +Base, -Name
            agent_register/5,           % +Node, ?Name0, +Entry, +Options, -Name
            agent_register_state/3,     % +Node, +Name, +State
            agent_unregister/2,         % +Node, +Name
            agent_payload_note/3,       % +Node, +Name, +Pred/Arity
            agent_payload_drop/3,       % +Node, +Name, +Pred/Arity
            agent_add_tokens/3,         % +Node, +Name, +Tokens
            agent_remove_tokens/3,      % +Node, +Name, +Tokens
            agent_hop_times/3,          % +Node, +Name, -Millis
            agent_record_hop/3          % +Node, +Name, +Hop
          ]).
:- use_module(guest_limits, [guest_module_init/1]).
:- autoload(library(error), [must_be/2, existence_error/2, permission_error/3]).
:- autoload(library(option), [option/3]).
:- autoload(library(lists), [member/2, subtract/3, union/3, append/3, last/2]).
:- autoload(library(apply), [maplist/2]).
:- autoload(library(aggregate), [aggregate_all/3]).

:- meta_predicate with_agents_locked(0).

/** <module> The agents of a node: their records and the registry mutex

What the platform knows of each agent on each node, apart from its code:
its handler and kind, its tokens, status, payload predicates, the hops
it made and the peer it came from, and the name of its module. The
facts are this module's; the other agent modules (agent_code.pl,
agent_records.pl, agent_execution.pl, agents.pl) read and change them
through the predicates exported here, under the registry mutex
(with_agents_locked/1) where a check and a change must be one step.

Every change that custody must hear of goes through agent_notify/3,
which calls the multifile hook agents:agent_changed/3. The hook keeps
the name of the module agents, the platform's face for agents (agents.pl
re-exports this module's public predicates), so that hosts and the
bounds and custody modules define it there.
*/

:- dynamic
    agent_entry/4,              % Node, Name, Handler, Kind
    agent_tokens_/3,            % Node, Name, Tokens
    agent_status_/3,            % Node, Name, Status
    agent_payload_/3,           % Node, Name, Pred/Arity
    agent_hops_/3,              % Node, Name, Hops
    agent_peer_/3.              % Node, Name, Peer (arrived from; absent: local)

:- multifile
    agents:agent_changed/3.     % +Event, +Node, +Name

%!  agents:agent_changed(+Event, +Node, +Name) is nondet.
%
%   Multifile hook, called (through agent_notify/3) after agent Name on
%   Node changed, outside the registry mutex. Event is `saved` (created,
%   payload or tokens changed), run(idle) / run(run) (its handler
%   returned / started) or `removed`. custody.pl implements it to keep
%   the agents a node holds on disk. Example:
%
%   ```
%   agents:agent_changed(removed, Node, Name) :-
%       debug(my_topic, '~p left ~w', [Name, Node]).
%   ```
%
%   Errors are not caught: a change that cannot be made durable is
%   reported to the caller.

%!  agent_notify(+Event, +Node, +Name) is det.
%
%   Call every clause of the hook agents:agent_changed/3 for Event.

agent_notify(Event, Node, Name) :-
    forall(agents:agent_changed(Event, Node, Name), true).

%!  with_agents_locked(:Goal) is semidet.
%
%   Run Goal holding the registry mutex. Goal must be quick and must
%   not do any I/O with peers.

with_agents_locked(Goal) :-
    with_mutex(dfrl_agents, Goal).

%!  agent_module(+Node, +Name, -Module) is det.
%
%   The module holding the code and payload of agent Name on Node.

agent_module(Node, Name, Module) :-
    (   module_of_(Name, Node, Module0)
    ->  Module = Module0
    ;   format(atom(Module), 'dfrl_agent@~w/~q', [Node, Name]),
        guest_module_init(Module),      % sizes of C-level work checked
        assertz(module_of_(Name, Node, Module))
    ).

%   The module names made so far (an agent's module outlives it, as
%   every SWI-Prolog module does; so does its name here): a hop asks for
%   it some ten times, and format/3 was a tenth of installing an agent.
:- dynamic module_of_/3.                % Name, Node, Module

%!  agent_exists(?Node, ?Name) is nondet.

agent_exists(Node, Name) :-
    agent_entry(Node, Name, _, _).

%!  agent_must_exist(+Node, +Name) is det.
%
%   @error existence_error(agent, Name) if Node holds no agent Name.

agent_must_exist(Node, Name) :-
    (   agent_entry(Node, Name, _, _)
    ->  true
    ;   existence_error(agent, Name)
    ).

%!  agent_property(?Node, ?Name, ?Property) is nondet.
%
%   Properties: handler(H), kind(K), tokens(L), status(S), payload(L),
%   module(M), hops(N), arrived(T): when its last hop arrived (this
%   node's clock; none for an agent that never moved), peer(P): the peer the agent arrived from
%   (agent_install/5 option peer(P), e.g. tls(Name) or ip(A,B,C,D)), or
%   `local` for an agent made or installed here without one.

agent_property(Node, Name, Property) :-
    agent_entry(Node, Name, Handler, Kind),
    agent_property_(Property, Node, Name, Handler, Kind).

agent_property_(handler(H), _, _, H, _).
agent_property_(kind(K), _, _, _, K).
agent_property_(tokens(T), Node, Name, _, _) :-
    agent_tokens_(Node, Name, T).
agent_property_(status(S), Node, Name, _, _) :-
    agent_status_(Node, Name, S).
agent_property_(payload(L), Node, Name, _, _) :-
    findall(P, agent_payload_(Node, Name, P), L).
agent_property_(module(M), Node, Name, _, _) :-
    agent_module(Node, Name, M).
agent_property_(hops(N), Node, Name, _, _) :-
    agent_hops_(Node, Name, Hops),
    length(Hops, N).
agent_property_(arrived(T), Node, Name, _, _) :-
    agent_hops_(Node, Name, Hops),
    last(Hops, hop(_, _, _, T)).
agent_property_(peer(P), Node, Name, _, _) :-
    (   agent_peer_(Node, Name, P0) -> P = P0 ; P = local ).

%!  agent_list(+Node, -Agents) is det.
%
%   Agents is a list of agent(Name, Handler, Kind, Status).

agent_list(Node, Agents) :-
    findall(agent(Name, Handler, Kind, Status),
            ( agent_entry(Node, Name, Handler, Kind),
              agent_status_(Node, Name, Status0),
              public_status(Status0, Status)
            ),
            Agents).

public_status(running(_), running) :- !.
public_status(departing(_), departing) :- !.
public_status(staged(_), staged) :- !.
public_status(S, S).

%!  agent_registered(+Node, +Name, -Registered) is det.
%
%   Registered is registered(Handler, Kind, Tokens, Payload, Hops), what
%   the registry holds of agent Name for its record (agent_export/3).
%
%   @error existence_error(agent, Name)

agent_registered(Node, Name, registered(Handler, Kind, Tokens, Payload, Hops)) :-
    agent_must_exist(Node, Name),
    % once/1: with several agents on Node, indexing on Node alone left a
    % choice point here (move_agent/2 then too, often)
    once(agent_entry(Node, Name, Handler, Kind)),
    once(agent_tokens_(Node, Name, Tokens)),
    findall(P, agent_payload_(Node, Name, P), Payload),
    once(agent_hops_(Node, Name, Hops)).

%!  agent_status(+Node, +Name, -Status) is det.
%
%   @error existence_error(agent, Name)

agent_status(Node, Name, Status) :-
    (   agent_status_(Node, Name, S)
    ->  Status = S
    ;   existence_error(agent, Name)
    ).

%!  agent_set_status(+Node, +Name, +Status) is det.

agent_set_status(Node, Name, Status) :-
    retractall(agent_status_(Node, Name, _)),
    assertz(agent_status_(Node, Name, Status)).

%!  agent_take_idle(+Node, +Name) is semidet.
%
%   If agent Name on Node is idle, mark it `expiring` (so that it cannot
%   be started, moved or cloned) and succeed; fail otherwise. For
%   agent_bounds.pl, which then purges it (agent_idle_limit).

agent_take_idle(Node, Name) :-
    with_agents_locked(
        (   agent_status_(Node, Name, idle)
        ->  agent_set_status(Node, Name, expiring)
        )).

%!  agent_fresh_name(+Node, +Base, -Name) is det.
%
%   Name is Base_N, not yet used on Node.

agent_fresh_name(Node, Base, Name) :-
    flag(dfrl_agent_names, N0, N0+1),
    N is N0 + 1,
    format(atom(Try), '~w_~d', [Base, N]),
    (   agent_entry(Node, Try, _, _)
    ->  agent_fresh_name(Node, Base, Name)
    ;   Name = Try
    ).

		 /*******************************
		 *     ENTERING AND LEAVING	*
		 *******************************/

%!  agent_register(+Node, ?Name0, +Entry, +Options, -Name) is det.
%
%   Enter an agent in the registry of Node, under the registry mutex,
%   as entry(Handler, Kind); its state follows with
%   agent_register_state/3. Name0 is the name asked for: unbound for a
%   fresh name agent_N, rename(_, Base) for a fresh name Base_N, or an
%   atom, which must be free. Options are those of agent_install/5:
%   max_agents(Max), peer(Peer) and max_per_peer(Max).
%
%   @error permission_error(create, agent, Name) if the name is taken.
%   @error resource_error(agents) if Node holds Max agents.
%   @error resource_error(peer_agents) if it holds Max agents of Peer.

agent_register(Node, Name0, entry(Handler, Kind), Options, Name) :-
    option(max_agents(Max), Options, infinite),
    option(peer(Peer), Options, local),
    must_be(ground, Peer),
    option(max_per_peer(MaxPeer), Options, infinite),
    with_agents_locked(( room_for_one(Node, Max),
                         room_for_one_of(Node, Peer, MaxPeer),
                         enter(Node, Name0, Handler, Kind, Name),
                         (   Peer == local
                         ->  true
                         ;   assertz(agent_peer_(Node, Name, Peer))
                         ) )).

room_for_one(_, infinite) :-
    !.
room_for_one(Node, Max) :-
    aggregate_all(count, agent_entry(Node, _, _, _), N),
    (   N < Max
    ->  true
    ;   throw(error(resource_error(agents), context(_, limit(Max))))
    ).

room_for_one_of(_, local, _) :-
    !.
room_for_one_of(_, _, infinite) :-
    !.
room_for_one_of(Node, Peer, Max) :-
    aggregate_all(count, agent_peer_(Node, _, Peer), N),
    (   N < Max
    ->  true
    ;   throw(error(resource_error(peer_agents), context(_, limit(Max))))
    ).

enter(Node, Name0, Handler, Kind, Name) :-
    var(Name0),
    !,
    agent_fresh_name(Node, agent, Name),
    assertz(agent_entry(Node, Name, Handler, Kind)).
enter(Node, rename(_, Base), Handler, Kind, Name) :-
    !,
    agent_fresh_name(Node, Base, Name),
    assertz(agent_entry(Node, Name, Handler, Kind)).
enter(Node, Name, Handler, Kind, Name) :-
    (   agent_entry(Node, Name, _, _)
    ->  permission_error(create, agent, Name)
    ;   assertz(agent_entry(Node, Name, Handler, Kind))
    ).

%!  agent_register_state(+Node, +Name, +State) is det.
%
%   Record the state of agent Name, just entered by agent_register/5:
%   State is state(Tokens, Payload, Hops, Status), Payload a list of
%   Pred/Arity. The status comes last: an agent with a status is whole.

agent_register_state(Node, Name, state(Tokens, Payload, Hops, Status)) :-
    assertz(agent_tokens_(Node, Name, Tokens)),
    forall(member(P, Payload), assertz(agent_payload_(Node, Name, P))),
    assertz(agent_hops_(Node, Name, Hops)),
    assertz(agent_status_(Node, Name, Status)).

%!  agent_unregister(+Node, +Name) is det.
%
%   Forget every record of agent Name on Node (its module is
%   agent_code.pl's to empty).

agent_unregister(Node, Name) :-
    with_agents_locked(
        ( retractall(agent_entry(Node, Name, _, _)),
          retractall(agent_tokens_(Node, Name, _)),
          retractall(agent_status_(Node, Name, _)),
          retractall(agent_payload_(Node, Name, _)),
          retractall(agent_hops_(Node, Name, _)),
          retractall(agent_peer_(Node, Name, _))
        )).

%!  agent_payload_note(+Node, +Name, +PI) is det.
%
%   Count the predicate PI (Pred/Arity) of agent Name as payload (once).

agent_payload_note(Node, Name, PI) :-
    (   agent_payload_(Node, Name, PI)
    ->  true
    ;   assertz(agent_payload_(Node, Name, PI))
    ).

%!  agent_payload_drop(+Node, +Name, +PI) is det.
%
%   Count the predicate PI of agent Name as payload no longer.

agent_payload_drop(Node, Name, PI) :-
    retractall(agent_payload_(Node, Name, PI)).

		 /*******************************
		 *            TOKENS		*
		 *******************************/

%!  agent_add_tokens(+Node, +Name, +Tokens) is det.

agent_add_tokens(Node, Name, Tokens) :-
    must_be(list, Tokens),
    maplist(must_be(ground), Tokens),
    agent_must_exist(Node, Name),
    with_agents_locked(
        ( retract(agent_tokens_(Node, Name, Old)),
          union(Old, Tokens, New),
          assertz(agent_tokens_(Node, Name, New))
        )),
    agent_notify(saved, Node, Name).

%!  agent_remove_tokens(+Node, +Name, +Tokens) is det.

agent_remove_tokens(Node, Name, Tokens) :-
    must_be(list, Tokens),
    agent_must_exist(Node, Name),
    with_agents_locked(
        ( retract(agent_tokens_(Node, Name, Old)),
          subtract(Old, Tokens, New),
          assertz(agent_tokens_(Node, Name, New))
        )),
    agent_notify(saved, Node, Name).

		 /*******************************
		 *             HOPS		*
		 *******************************/

%!  agent_hop_times(+Node, +Name, -Millis) is det.
%
%   Millis lists the duration of each hop the agent made, oldest first,
%   measured from the start of move_agent at the source to the start of
%   its handler at the destination.

agent_hop_times(Node, Name, Millis) :-
    agent_must_exist(Node, Name),
    agent_hops_(Node, Name, Hops),
    findall(Ms, ( member(hop(_, _, T0, T1), Hops), Ms is (T1-T0)*1000 ), Millis).

%!  agent_record_hop(+Node, +Name, +Hop) is semidet.
%
%   Append Hop, hop(From, To, Departed, Arrived) (get_time/1 stamps), to
%   the hop record of agent Name on Node, keeping the last 100 hops (the
%   record travels with the agent: 74 bytes a hop).
%   Fails if Name is not on Node.

agent_record_hop(Node, Name, Hop) :-
    Hop = hop(_, _, T0, T1),
    must_be(number, T0),
    must_be(number, T1),
    with_agents_locked(
        (   retract(agent_hops_(Node, Name, Hops0))
        ->  append(Hops0, [Hop], Hops1),
            keep_last(Hops1, Hops),
            assertz(agent_hops_(Node, Name, Hops))
        )).

max_hops_kept(100).

keep_last(List, Kept) :-
    max_hops_kept(Max),
    length(List, N),
    (   N =< Max
    ->  Kept = List
    ;   Drop is N - Max,
        length(Prefix, Drop),
        append(Prefix, Kept, List)
    ).
