:- module(agent_code,
          [ replace_guid/4,             % +Term0, +From, +To, -Term
            handler_clauses/3,          % +Module, +Handler, -Clauses
            install_clauses/2,          % +Module, +Clauses
            install_preds/2,            % +Module, +Preds
            module_clauses/3,           % +Module, -Preds, -Clauses
            empty_module/1,             % +Module
            agent_add_payload/3,        % +Node, +Name, +Preds
            agent_add_facts/3,          % +Node, +Name, +Facts
            agent_remove_payload/3      % +Node, +Name, +Preds
          ]).
:- use_module(agent_registry,
              [ agent_module/3, agent_must_exist/2, agent_notify/3, agent_payload_note/3,
                agent_payload_drop/3 ]).
:- autoload(library(error), [must_be/2]).
:- autoload(library(lists), [member/2]).
:- autoload(library(apply), [maplist/2, maplist/3]).

/** <module> The code of an agent: its module's clauses and its payload

An agent's code lives in a module of its own (agent_module/3): its
handler's clauses and the payload facts, with the atom `guid` replaced
by the agent's name (on terms, never on text). Goals in the handler run
in that module, which inherits from `user`, so helper predicates of the
program are visible and the agent's own asserts land in its module,
i.e. they are the agent's state and travel with it.

This module and its users in the agents family (agents.pl: creation,
agent_records.pl: export and install, agent_execution.pl: removal) are
the one place where the platform writes into modules other than its
own, by design: an agent module holds nothing but the agent's own
state. Other platform modules change an agent only through the exported
predicates (e.g. agent_add_payload/3); an agent program writes its own
module, which is where its handler runs.
*/

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

%!  handler_clauses(+Module, +Handler, -Clauses) is det.
%
%   Clauses are the clauses (Head:-Body) of Handler/N, 3 =< N =< 16,
%   defined (not imported) in Module.

handler_clauses(M, Handler, Clauses) :-
    findall((H:-B),
            ( between(3, 16, A),
              functor(H, Handler, A),
              current_predicate(M:Handler/A),
              \+ predicate_property(M:H, imported_from(_)),
              clause(M:H, B)
            ),
            Clauses).

%!  install_clauses(+Module, +Clauses) is det.
%
%   Assert each of Clauses (Head:-Body or a fact) at the end of its
%   predicate in Module, which is made dynamic there first.

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

%!  install_preds(+Module, +Preds) is det.
%
%   Declare each of Preds (Pred/Arity) dynamic in Module, so that a
%   predicate without clauses exists there too.

install_preds(M, Preds) :-
    forall(member(F/A, Preds), ( functor(H, F, A), ensure_dynamic(M, H) )).

ensure_dynamic(M, H) :-
    (   predicate_property(M:H, dynamic),
        \+ predicate_property(M:H, imported_from(_))
    ->  true
    ;   functor(H, F, A),
        dynamic(M:F/A)
    ).

%!  empty_module(+Module) is det.
%
%   Retract every clause of every dynamic predicate defined in Module.

empty_module(M) :-
    forall(( current_predicate(_, M:H),
             \+ predicate_property(M:H, imported_from(_)),
             predicate_property(M:H, dynamic)
           ),
           retractall(M:H)).

%!  module_clauses(+Module, -Preds, -Clauses) is det.
%
%   Preds are the dynamic predicates defined in Module (Pred/Arity),
%   Clauses their clauses, predicate by predicate.

module_clauses(M, Preds, Clauses) :-
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
    agent_must_exist(Node, Name),
    agent_module(Node, Name, M),
    forall(member(P0, Preds),
           ( pred_indicator(P0, F/A),
             copy_payload(M, Name, F, A),
             agent_payload_note(Node, Name, F/A)
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
    agent_must_exist(Node, Name),
    agent_module(Node, Name, M),
    forall(member(F, Facts),
           ( install_clause(M, F),
             functor(F, P, A),
             agent_payload_note(Node, Name, P/A)
           )),
    agent_notify(saved, Node, Name).

%!  agent_remove_payload(+Node, +Name, +Preds) is det.
%
%   Remove the payload predicates Preds (their clauses) from the agent.

agent_remove_payload(Node, Name, Preds) :-
    must_be(list, Preds),
    agent_must_exist(Node, Name),
    agent_module(Node, Name, M),
    forall(member(P0, Preds),
           ( pred_indicator(P0, F/A),
             functor(H, F, A),
             (   predicate_property(M:H, dynamic)
             ->  retractall(M:H)
             ;   true
             ),
             agent_payload_drop(Node, Name, F/A)
           )),
    agent_notify(saved, Node, Name).
