:- module(dfrl_payload,
          [ robot_options/4,            % +Agent, +State, +Timeout, -Options
            itinerary_kind/3,           % +Module, +Agent, -Kind
            carried/3,                  % +Module, +Agent, -Carried
            alone/3,                    % +Module, +Agent, +State
            last_stop/3,                % +Module, +Agent, +Index
            next_method/5               % +Method, +Carried, +State, -Next, -Good
          ]).
:- use_module('../tartarus', [current_node/1]).
:- use_module(dfrl_lease, [lease_custody/3]).
:- use_module(dfrl_aggregation, [method_applies_to/2]).

/** <module> What the dFRL agent's payload says

Read-only questions about a dFRL agent (dfrl_agent.pl) answered from
the payload facts it carries in its own module M (dfrl_plan/2,
dfrl_carries_of/2, dfrl_itinerary_of/2) and from its round state. An
agent created before a fact existed gets that fact's old meaning. No
predicate here writes.
*/

%!  robot_options(+Agent, +State, +Timeout, -Options) is det.
%
%   Options of a table read or write of Agent in the round of State
%   (contract K4: where a read or write comes from): timeout(Timeout),
%   round(N), agent(Agent), epoch(E).

robot_options(Agent, S, Timeout, [timeout(Timeout), round(Round), agent(Agent),
                                  epoch(Epoch)]) :-
    get_dict(round, S, Round),
    current_node(Node),
    lease_custody(Node, Agent, custody(Epoch, _, _)).

%!  itinerary_kind(+Module, +Agent, -Kind) is det.
%
%   Kind is the agent's itinerary: chain (also for an agent created
%   before trees existed) or tree(K).

itinerary_kind(M, Agent, Kind) :-
    (   catch(M:dfrl_itinerary_of(Agent, K), error(existence_error(_, _), _), fail)
    ->  Kind = K
    ;   Kind = chain
    ).

%!  carried(+Module, +Agent, -Carried) is det.
%
%   What the agent carries: tables or params (an agent created before
%   params existed has no dfrl_carries_of/2 fact: tables).

carried(M, Agent, Carried) :-
    (   catch(M:dfrl_carries_of(Agent, C), error(existence_error(_, _), _), fail)
    ->  Carried = C
    ;   Carried = tables
    ).

%!  alone(+Module, +Agent, +State) is semidet.
%
%   The round of State read no robot but its own, of an itinerary of
%   several: it federated nothing, so it writes nothing (not even that
%   robot's own table back), so that a copy cut off from every other
%   stop writes nothing in a round that a resurrected copy may run too
%   (lease_watch.pl).

alone(M, Agent, S) :-
    get_dict(visited, S, [_]),
    M:dfrl_plan(Agent, plan(Itinerary, _, _, _, _)),
    Itinerary = [_, _|_].

%!  last_stop(+Module, +Agent, +Index) is semidet.
%
%   Index is the last stop of the agent's itinerary.

last_stop(M, Agent, Index) :-
    M:dfrl_plan(Agent, plan(Itinerary, _, _, _, _)),
    length(Itinerary, N),
    Index =:= N - 1.

%!  next_method(+Method, +Carried, +State, -Next, -Good) is det.
%
%   The method of the next round and the last method that worked. A round
%   whose method failed (State has an error) falls back to the last method
%   that completed a round (the state's `good`), or to average when none
%   did or that one was the failing method: a method that throws costs one
%   round, not the run, and sync robots waiting for a share get one again.
%   A method that works is the new fallback.

next_method(Method, Carried, S, Next, Good) :-
    (   get_dict(good, S, Good0) -> true ; Good0 = none ),
    (   get_dict(error, S, _)
    ->  (   Good0 \== none, Good0 \== Method, method_applies_to(Good0, Carried)
        ->  Next = Good0
        ;   Next = average
        ),
        Good = Next
    ;   Next = Method,
        Good = Method
    ).
