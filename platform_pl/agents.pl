:- module(agents,
          [ agent_create/4,             % ?Name, +Handler, +Options, +Node
            agent_execute/4,            % +Node, +Name, +Link, +Event
            agent_purge/2,              % +Node, +Name
            agent_exists/2,             % ?Node, ?Name
            agent_property/3,           % ?Node, ?Name, ?Property
            agent_list/2,               % +Node, -Agents
            agent_add_payload/3,        % +Node, +Name, +Preds
            agent_add_facts/3,          % +Node, +Name, +Facts
            agent_remove_payload/3,     % +Node, +Name, +Preds
            agent_add_tokens/3,         % +Node, +Name, +Tokens
            agent_remove_tokens/3,      % +Node, +Name, +Tokens
            agent_module/3,             % +Node, +Name, -Module
            agent_export/3,             % +Node, +Name, -Record
            agent_install/4,            % +Node, +Record, +Status, -Name
            agent_install/5,            % +Node, +Record, +Status, -Name, +Options
            agent_remove/2,             % +Node, +Name
            agent_set_status/3,         % +Node, +Name, +Status
            agent_status/3,             % +Node, +Name, -Status
            agent_take_idle/2,          % +Node, +Name
            agent_hop_times/3,          % +Node, +Name, -Millis
            agent_record_hop/3,         % +Node, +Name, +Hop
            agent_fresh_name/3,         % +Node, +Base, -Name
            current_agent/1,            % -Name
            replace_guid/4,             % +Term0, +From, +To, -Term
            with_agents_locked/1,       % :Goal
            agent_notify/3              % +Event, +Node, +Name
          ]).
:- use_module(node,
              [ current_node/1, node_set_current/1, node_clear_current/0,
                node_property/2 ]).
:- use_module(worker_pool, [pool_run/3, pool_signal/3]).
:- use_module(hop_probe, [hop_probe/1]).      % compiled away unless benchmarking
:- use_module(agent_bounds, [bounds_call/4, bounds_stopped/3, bounds_warning/2]).
:- use_module(guest_limits, [guest_module_init/1]).
:- autoload(library(error),
            [must_be/2, existence_error/2, permission_error/3, domain_error/2]).
:- autoload(library(option), [option/2, option/3]).
:- autoload(library(lists), [member/2, subtract/3, union/3, max_member/2, append/3,
                             last/2]).
:- autoload(library(apply), [maplist/2, maplist/3, include/3]).
:- autoload(library(aggregate), [aggregate_all/3]).

:- meta_predicate with_agents_locked(0).

/** <module> Agents on a node: registry, code, payload, tokens, threads

An agent is a name, a handler predicate, a kind (mobile or static), a
list of tokens and a private module that holds its code: the handler's
clauses and the payload facts, with the atom `guid` replaced by the
agent's name (on terms, never on text). Goals in the handler run in that
module, which inherits from `user`, so helper predicates of the program
are visible and the agent's own asserts land in its module, i.e. they
are the agent's state and travel with it.

A running agent has a thread. When its handler returns the agent stays
on the node, idle, until it is executed again, moved or purged.

This module owns the agents' modules: it creates them, asserts the
agent's code and payload into them and retracts it all when the agent
leaves. That is the one place where the platform writes into modules
other than its own, and it is by design: an agent module holds nothing
but the agent's own state. Other platform modules change an agent only
through the predicates exported here (e.g. agent_record_hop/3); an agent
program writes its own module, which is where its handler runs.
*/

:- dynamic
    agent_entry/4,              % Node, Name, Handler, Kind
    agent_tokens_/3,            % Node, Name, Tokens
    agent_status_/3,            % Node, Name, Status
    agent_payload_/3,           % Node, Name, Pred/Arity
    agent_hops_/3,              % Node, Name, Hops
    agent_peer_/3.              % Node, Name, Peer (arrived from; absent: local)

:- thread_local
    current_agent_tl/1.

:- multifile
    node:node_stopping/1,
    agent_changed/3.            % +Event, +Node, +Name

%   A stopping node forgets its agents without telling the custody hook:
%   stopping a node is not purging its agents, a node restarted with its
%   store recovers them.
node:node_stopping(Node) :-
    forall(agent_entry(Node, Name, _, _),
           catch(purge(Node, Name, quiet), _, true)).

%!  agent_changed(+Event, +Node, +Name) is nondet.
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
%   Call every clause of the hook agent_changed/3 for Event.

agent_notify(Event, Node, Name) :-
    forall(agent_changed(Event, Node, Name), true).

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

%!  agent_create(?Name, +Handler, +Options, +Node) is det.
%
%   Register a new agent on Node without starting it. An unbound Name is
%   bound to a fresh one. The clauses of Handler/N (N >= 3) in the
%   source module are copied into the agent's module with `guid`
%   replaced by Name. Options:
%
%     - kind(+Kind)        `mobile` (default) or `static`
%     - tokens(+List)      tokens the agent carries (default: the node's)
%     - payload(+Preds)    payload predicates, as for agent_add_payload/3
%     - module(+Module)    where Handler and payload are defined
%                          (default `user`)
%     - events(+List)      the Handler/Arity events peers may post to it
%                          (default: every arity of Handler it carries;
%                          kept as the fact '$agent_events'(List) in its
%                          module, so it travels with it)
%
%   @error permission_error(create, agent, Name) if the name is taken.
%   @error existence_error(handler, Handler/3) if Handler has no clauses.

agent_create(Name, Handler0, Options, Node) :-
    must_be(list, Options),
    strip_handler(Handler0, Options, SrcModule, Handler),
    option(kind(Kind), Options, mobile),
    must_be(oneof([mobile, static]), Kind),
    (   option(tokens(Tokens), Options)
    ->  must_be(list, Tokens)
    ;   node_property(Node, tokens(Tokens))
    ->  true
    ;   existence_error(platform, Node)
    ),
    handler_clauses(SrcModule, Handler, Templates),
    (   Templates == []
    ->  existence_error(handler, Handler/3)
    ;   true
    ),
    with_agents_locked(reserve_name(Node, Name, Handler, Kind)),
    agent_module(Node, Name, M),
    replace_guid(Templates, guid, Name, Clauses),
    install_clauses(M, Clauses),
    (   option(events(Events), Options)
    ->  must_be(list, Events),
        install_clause(M, '$agent_events'(Events))
    ;   true
    ),
    assertz(agent_tokens_(Node, Name, Tokens)),
    assertz(agent_hops_(Node, Name, [])),
    assertz(agent_status_(Node, Name, idle)),
    (   option(payload(Preds), Options)
    ->  agent_add_payload(Node, Name, Preds)
    ;   agent_notify(saved, Node, Name)
    ).

strip_handler(M:H, _, M, H) :-
    !,
    must_be(atom, H).
strip_handler(H, Options, M, H) :-
    must_be(atom, H),
    option(module(M), Options, user).

reserve_name(Node, Name, Handler, Kind) :-
    (   var(Name)
    ->  agent_fresh_name(Node, agent, Name)
    ;   must_be(atom, Name),
        (   agent_entry(Node, Name, _, _)
        ->  permission_error(create, agent, Name)
        ;   true
        )
    ),
    assertz(agent_entry(Node, Name, Handler, Kind)).

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

handler_clauses(M, Handler, Clauses) :-
    findall((H:-B),
            ( between(3, 16, A),
              functor(H, Handler, A),
              current_predicate(M:Handler/A),
              \+ predicate_property(M:H, imported_from(_)),
              clause(M:H, B)
            ),
            Clauses).

%!  replace_guid(+Term0, +From, +To, -Term) is det.
%
%   Term is Term0 with every occurrence of the atom From replaced by To.
%   Strings, numbers and atoms that merely contain From are untouched;
%   variables keep their sharing.

replace_guid(T0, From, To, T) :-
    (   T0 == From
    ->  T = To
    ;   compound(T0)
    ->  compound_name_arguments(T0, F, Args0),
        maplist(replace_in(From, To), Args0, Args),
        compound_name_arguments(T, F, Args)
    ;   T = T0
    ).

replace_in(From, To, A0, A) :-
    replace_guid(A0, From, To, A).

install_clauses(M, Clauses) :-
    forall(member(Cl, Clauses), install_clause(M, Cl)).

install_clause(M, (H:-B)) :-
    !,
    ensure_dynamic(M, H),
    (   B == true
    ->  assertz(M:H)
    ;   assertz(M:(H:-B))
    ).
install_clause(M, H) :-
    ensure_dynamic(M, H),
    assertz(M:H).

ensure_dynamic(M, H) :-
    (   predicate_property(M:H, dynamic),
        \+ predicate_property(M:H, imported_from(_))
    ->  true
    ;   functor(H, F, A),
        dynamic(M:F/A)
    ).

%!  agent_exists(?Node, ?Name) is nondet.

agent_exists(Node, Name) :-
    agent_entry(Node, Name, _, _).

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

must_exist(Node, Name) :-
    (   agent_entry(Node, Name, _, _)
    ->  true
    ;   existence_error(agent, Name)
    ).

		 /*******************************
		 *            PAYLOAD		*
		 *******************************/

%!  agent_add_payload(+Node, +Name, +Preds) is det.
%
%   Preds is a list of Pred/Arity or (Pred,Arity). The clauses of each in
%   `user` whose first argument is `guid` or Name (and all clauses of a
%   predicate with arity 0) are copied into the agent, specialised to
%   it. A predicate with no clauses is declared (empty) so the agent can
%   assert into it. Payload travels with the agent.

agent_add_payload(Node, Name, Preds) :-
    must_be(list, Preds),
    must_exist(Node, Name),
    agent_module(Node, Name, M),
    forall(member(P0, Preds),
           ( pred_indicator(P0, F/A),
             copy_payload(M, Name, F, A),
             (   agent_payload_(Node, Name, F/A)
             ->  true
             ;   assertz(agent_payload_(Node, Name, F/A))
             )
           )),
    agent_notify(saved, Node, Name).

pred_indicator(F/A, F/A) :-
    !,
    must_be(atom, F),
    must_be(nonneg, A).
pred_indicator((F,A), F/A) :-
    !,
    must_be(atom, F),
    must_be(nonneg, A).
pred_indicator(X, _) :-
    throw(error(type_error(predicate_indicator, X), _)).

copy_payload(M, Name, F, A) :-
    dynamic(M:F/A),
    functor(H, F, A),
    (   current_predicate(user:F/A),
        \+ predicate_property(user:H, imported_from(_))
    ->  findall(Cl, payload_template(H, Name, Cl), Templates),
        replace_guid(Templates, guid, Name, Clauses),
        forall(member(Cl, Clauses),
               ( Cl = (H1:-B1),
                 (   clause(M:H1, B1)
                 ->  true
                 ;   install_clause(M, Cl)
                 )
               ))
    ;   true
    ).

payload_template(H, Name, (H:-B)) :-
    clause(user:H, B),
    (   compound(H)
    ->  arg(1, H, First),
        ( First == guid ; First == Name )
    ;   true
    ).

%!  agent_add_facts(+Node, +Name, +Facts) is det.
%
%   Assert each of Facts (a list of callable terms, not module
%   qualified) into agent Name and make its predicate payload, so the
%   facts travel with the agent. For a program that gives a new agent
%   its initial state without asserting it into `user` first.
%
%   @error type_error(callable, Fact)

agent_add_facts(Node, Name, Facts) :-
    must_be(list, Facts),
    maplist(must_be(callable), Facts),
    forall(member(F, Facts),
           (   F = _:_
           ->  throw(error(type_error(unqualified_fact, F), _))
           ;   true
           )),
    must_exist(Node, Name),
    agent_module(Node, Name, M),
    forall(member(F, Facts),
           ( install_clause(M, F),
             functor(F, P, A),
             (   agent_payload_(Node, Name, P/A)
             ->  true
             ;   assertz(agent_payload_(Node, Name, P/A))
             )
           )),
    agent_notify(saved, Node, Name).

%!  agent_remove_payload(+Node, +Name, +Preds) is det.
%
%   Remove the payload predicates Preds (their clauses) from the agent.

agent_remove_payload(Node, Name, Preds) :-
    must_be(list, Preds),
    must_exist(Node, Name),
    agent_module(Node, Name, M),
    forall(member(P0, Preds),
           ( pred_indicator(P0, F/A),
             functor(H, F, A),
             (   predicate_property(M:H, dynamic)
             ->  retractall(M:H)
             ;   true
             ),
             retractall(agent_payload_(Node, Name, F/A))
           )),
    agent_notify(saved, Node, Name).

		 /*******************************
		 *            TOKENS		*
		 *******************************/

%!  agent_add_tokens(+Node, +Name, +Tokens) is det.

agent_add_tokens(Node, Name, Tokens) :-
    must_be(list, Tokens),
    maplist(must_be(ground), Tokens),
    must_exist(Node, Name),
    with_agents_locked(
        ( retract(agent_tokens_(Node, Name, Old)),
          union(Old, Tokens, New),
          assertz(agent_tokens_(Node, Name, New))
        )),
    agent_notify(saved, Node, Name).

%!  agent_remove_tokens(+Node, +Name, +Tokens) is det.

agent_remove_tokens(Node, Name, Tokens) :-
    must_be(list, Tokens),
    must_exist(Node, Name),
    with_agents_locked(
        ( retract(agent_tokens_(Node, Name, Old)),
          subtract(Old, Tokens, New),
          assertz(agent_tokens_(Node, Name, New))
        )),
    agent_notify(saved, Node, Name).

		 /*******************************
		 *           EXECUTION		*
		 *******************************/

%!  agent_execute(+Node, +Name, +Link, +Event) is det.
%
%   Start agent Name in a new thread: its handler is called as
%   Handler(Name, Link, Event) in the agent's module.
%
%   @error existence_error(agent, Name)
%   @error permission_error(execute, agent, Name) if it is already
%   running or in transit.

agent_execute(Node, Name, Link, Event) :-
    must_exist(Node, Name),
    with_agents_locked(start_thread(Node, Name, Link, Event)).

start_thread(Node, Name, Link, Event) :-
    agent_status_(Node, Name, Status),
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
        (   agent_status_(Node, Name, starting)
        ->  agent_set_status(Node, Name, running(Me)),
            Run = true
        ;   Run = false                 % purged or moved before it started
        )),
    (   Run == true
    ->  catch(agent_notify(run(run), Node, Name), E0,
              print_message(warning, E0)),
        setup_call_cleanup(
            enter_agent(Node, Name),
            run_agent(Node, Name, Link, Event),
            leave_agent),
        with_agents_locked(
            (   agent_status_(Node, Name, running(Me))
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
    (   agent_entry(Node, Name, Handler, _)
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
    (   agent_entry(Node, Name, _, _)
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
    must_exist(Node, Name),
    (   agent_status_(Node, Name, running(Tid)),
        \+ thread_self(Tid)
    ->  pool_signal(agents, Tid, agents:purge_if_running(Name))
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
    forall(( current_predicate(_, M:H),
             \+ predicate_property(M:H, imported_from(_)),
             predicate_property(M:H, dynamic)
           ),
           retractall(M:H)),
    with_agents_locked(
        ( retractall(agent_entry(Node, Name, _, _)),
          retractall(agent_tokens_(Node, Name, _)),
          retractall(agent_status_(Node, Name, _)),
          retractall(agent_payload_(Node, Name, _)),
          retractall(agent_hops_(Node, Name, _)),
          retractall(agent_peer_(Node, Name, _))
        )).

		 /*******************************
		 *        EXPORT / INSTALL		*
		 *******************************/

%!  agent_export(+Node, +Name, -Record) is det.
%
%   Record is a self-contained copy of the agent: everything needed to
%   install it on another node, save it to a file or clone it:
%   agent(Name, Handler, Kind, Tokens, Payload, Preds, Clauses, Hops).
%   Tokens are the agent's own, for uses inside this process (custody,
%   checkpoints): a record that leaves it carries none (migration.pl
%   sends [], persist.pl saves []).

agent_export(Node, Name, agent(Name, Handler, Kind, Tokens, Payload,
                               Preds, Clauses, Hops)) :-
    must_exist(Node, Name),
    % once/1: with several agents on Node, indexing on Node alone left a
    % choice point here (move_agent/2 then too, often)
    once(agent_entry(Node, Name, Handler, Kind)),
    once(agent_tokens_(Node, Name, Tokens)),
    findall(P, agent_payload_(Node, Name, P), Payload),
    once(agent_hops_(Node, Name, Hops)),
    agent_module(Node, Name, M),
    findall(F/A,
            ( current_predicate(_, M:H),
              \+ predicate_property(M:H, imported_from(_)),
              predicate_property(M:H, dynamic),
              functor(H, F, A)
            ),
            Preds),
    pred_clauses(Preds, M, Clauses).

%   The clauses of each predicate, straight into one list (findall/3 of
%   the clauses themselves would copy a large payload twice more). A
%   predicate of exactly one fact, which is what a payload usually is
%   (the dFRL agent's state, a table), is read by calling it: its head
%   is built from the clause directly, where clause/3 decompiles it
%   (SWI-Prolog 9.0.4, a fact holding 100,000 floats: 0.8 ms against
%   3.1 ms). Every other predicate is decompiled clause by clause. An
%   agent changing its clauses while it is exported (a clone of a
%   running agent) gets each predicate as it was at one instant, as
%   before.
pred_clauses([], _, []).
pred_clauses([F/A|Preds], M, Clauses) :-
    functor(H, F, A),
    (   one_fact(M:H)
    ->  (   catch(M:H, _, fail)
        ->  Clauses = [(H:-true)|Rest]
        ;   Clauses = Rest              % retracted meanwhile
        )
    ;   findall(Ref, nth_clause(M:H, _, Ref), Refs),
        ref_clauses(Refs, M, Clauses, Rest)
    ),
    pred_clauses(Preds, M, Rest).

one_fact(MH) :-
    predicate_property(MH, number_of_clauses(1)),
    predicate_property(MH, number_of_rules(0)),
    \+ predicate_property(MH, tabled).

ref_clauses([], _, Rest, Rest).
ref_clauses([Ref|Refs], M, Clauses, Rest) :-
    (   catch(clause(M:H, B, Ref), _, fail)
    ->  Clauses = [(H:-B)|Clauses1]
    ;   Clauses = Clauses1              % retracted meanwhile
    ),
    ref_clauses(Refs, M, Clauses1, Rest).

%!  agent_install(+Node, +Record, +Status, -Name) is det.
%
%   Install an agent from its Record with Status. If Record's name is
%   taken on Node, Name is the name of Record unless the record asks for
%   a fresh one: rename(Base) as name makes a fresh name Base_N and
%   replaces the old name by it in all clauses.
%
%   @error permission_error(create, agent, Name) if the name is taken.
%   @error type_error(agent_record, Record) for a malformed record.

agent_install(Node, Record, Status, Name) :-
    agent_install(Node, Record, Status, Name, []).

%!  agent_install(+Node, +Record, +Status, -Name, +Options) is det.
%
%   As agent_install/4. Options:
%
%     - max_agents(+Max)  refuse the agent if Node holds Max agents
%                         already (an integer or `infinite`, the
%                         default). Counted and registered under the
%                         registry mutex, so simultaneous arrivals never
%                         make more than Max.
%     - peer(+Peer)       the peer the agent arrives from (a ground
%                         term; default `local`): its property peer(P)
%     - max_per_peer(+Max) refuse the agent if Node holds Max agents of
%                         Peer already (default `infinite`; never for
%                         `local`), counted as max_agents is.
%
%   @error resource_error(agents) if Node holds Max agents.
%   @error resource_error(peer_agents) if it holds Max agents of Peer.

agent_install(Node, Record, Status, Name, Options) :-
    check_record(Record),
    option(max_agents(Max), Options, infinite),
    option(peer(Peer), Options, local),
    must_be(ground, Peer),
    option(max_per_peer(MaxPeer), Options, infinite),
    Record = agent(Name0, Handler, Kind, Tokens, Payload, Preds, Clauses0, Hops),
    with_agents_locked(( room_for_one(Node, Max),
                         room_for_one_of(Node, Peer, MaxPeer),
                         install_entry(Node, Name0, Handler, Kind, Name),
                         (   Peer == local
                         ->  true
                         ;   assertz(agent_peer_(Node, Name, Peer))
                         ) )),
    (   Name0 = rename(Old, _)
    ->  replace_guid(Clauses0, Old, Name, Clauses)
    ;   Clauses = Clauses0
    ),
    agent_module(Node, Name, M),
    forall(member(F/A, Preds), ( functor(H, F, A), ensure_dynamic(M, H) )),
    install_clauses(M, Clauses),
    assertz(agent_tokens_(Node, Name, Tokens)),
    forall(member(P, Payload), assertz(agent_payload_(Node, Name, P))),
    assertz(agent_hops_(Node, Name, Hops)),
    assertz(agent_status_(Node, Name, Status)).

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

install_entry(Node, rename(_, Base), Handler, Kind, Name) :-
    !,
    agent_fresh_name(Node, Base, Name),
    assertz(agent_entry(Node, Name, Handler, Kind)).
install_entry(Node, Name, Handler, Kind, Name) :-
    (   agent_entry(Node, Name, _, _)
    ->  permission_error(create, agent, Name)
    ;   assertz(agent_entry(Node, Name, Handler, Kind))
    ).

check_record(Record) :-
    (   Record = agent(Name, Handler, Kind, Tokens, Payload, Preds, Clauses, Hops),
        ( atom(Name) ; Name = rename(O, B), atom(O), atom(B) ),
        atom(Handler),
        memberchk(Kind, [mobile, static]),
        is_list(Tokens), ground(Tokens),
        is_list(Payload),
        is_list(Preds),
        forall(member(P, Preds), (P = F/A, atom(F), integer(A), A >= 0)),
        is_list(Clauses),
        forall(member(C, Clauses), valid_clause(C)),
        is_list(Hops)
    ->  true
    ;   throw(error(type_error(agent_record, Record), _))
    ).

valid_clause((H:-_)) :-
    !,
    valid_head(H).
valid_clause(H) :-
    valid_head(H).

%   Not qualified, and no control construct: a head (a:-b) would be
%   asserted as a rule.
valid_head(H) :-
    callable(H),
    \+ H = (_:_),
    functor(H, F, A),
    \+ memberchk(F/A, [ (:-)/2, (:-)/1, (?-)/1, (-->)/2, (',')/2, (;)/2,
                        (->)/2, (*->)/2, (\+)/1, (@)/2 ]).

%!  agent_hop_times(+Node, +Name, -Millis) is det.
%
%   Millis lists the duration of each hop the agent made, oldest first,
%   measured from the start of move_agent at the source to the start of
%   its handler at the destination.

agent_hop_times(Node, Name, Millis) :-
    must_exist(Node, Name),
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
