:- module(dfrl_agent,
          [ dfrl_tour/3,                % +Agent, +Link, +Event (the handler)
            dfrl_tour_main/2,           % +Agent, +Link
            dfrl_create/4,              % +Node, ?Name, +Plan, +Options
            aggregate_tables/3,         % +Method, +Tables, -Table
            dfrl_method/1               % ?Method
          ]).
:- use_module('../tartarus').
:- use_module('../agents', [agent_property/3, current_agent/1]).
:- autoload(library(error), [must_be/2, domain_error/2]).
:- autoload(library(lists), [nth0/3, append/3, last/2, sum_list/2]).
:- autoload(library(option), [option/2, option/3]).
:- autoload(library(debug), [debug/3]).

/** <module> The dFRL itinerary agent (Algorithm 1 as a mobile agent)

One round: at the first stop the agent reads the robot's Q-table and
starts an aggregate; it migrates along the itinerary, folding each
robot's table into the aggregate (forward pass); at the last stop it
finishes the aggregate and writes it into that robot, then walks back
writing it into every robot it passes (backward pass). At the first stop
it logs the round, rests and starts the next round, until its round
budget is spent or it is told to stop.

Everything the agent needs travels as payload facts:

  - dfrl_plan(Agent, plan(Itinerary, Rounds, RestSeconds, LogFile, Timeout))
    Itinerary is a list of stop(Host, Port, Robot).
  - dfrl_method_of(Agent, Method)
  - dfrl_state(Agent, State): where it is in the round and its aggregate.

Robots are reached through the bridge predicates get_qtable/3,
set_qtable/3 and get_qtable_and_visits/4 (pybridge/robot_bridge.pl),
which the robot node provides. Tables are qtable(Shape, Values) with
Values a flat row-major list of floats.

## Aggregation methods

Built in: `average` (element-wise mean), `max` (element-wise maximum)
and `visit_average` (mean weighted by how often each state-action pair
was visited; pairs nobody visited get the plain mean). A new method is
plain Prolog: clauses of the multifile hooks below, loaded into running
nodes with load_program_at/3 and selected with the control command
method(Name). Example (platform_pl/agents/examples/median_method.pl):

```
:- multifile dfrl_agent:aggregate_init/3, dfrl_agent:aggregate_step/4,
             dfrl_agent:aggregate_final/3.
dfrl_agent:aggregate_init(min, qtable(_, V), V).
dfrl_agent:aggregate_step(min, Acc0, qtable(_, V), Acc) :-
    maplist([A,B,C]>>(C is min(A,B)), Acc0, V, Acc).
dfrl_agent:aggregate_final(min, Acc, Acc).
```

A method that needs visit counts also declares
dfrl_agent:method_uses_visits(Name); its hooks then receive
qtable_visits(Shape, Values, Visits).

## Control

A node declares the platform event dfrl_control/3; posting
[dfrl_control, platform, Link, Command] to the node of the first stop
queues Command, which the agent applies when it starts its next round:
join(stop(Host, Port, Robot)) adds a robot at the end of the itinerary,
method(Name) switches the aggregation method, stop ends after the
current round.
*/

:- multifile
    aggregate_init/3,           % +Method, +Table, -Acc
    aggregate_step/4,           % +Method, +Acc0, +Table, -Acc
    aggregate_final/3,          % +Method, +Acc, -Values
    method_uses_visits/1.       % ?Method

:- dynamic
    pending/1,                  % Command queued on this node
    dfrl_plan/2, dfrl_method_of/2, dfrl_state/2.

:- initialization(platform_event(dfrl_control/3)).

%!  dfrl_control(+Platform, +Link, +Command) is det.
%
%   Platform event: queue Command for the agent's next round.

user:dfrl_control(platform, _Link, Command) :-
    (   valid_command(Command)
    ->  assertz(dfrl_agent:pending(Command))
    ;   print_message(warning, format("dfrl: ignored control command ~p", [Command]))
    ).

valid_command(join(stop(H, P, R))) :- atomic(H), integer(P), atom(R).
valid_command(method(M)) :- atom(M).
valid_command(stop).

%!  dfrl_method(?Method) is nondet.
%
%   Method is an aggregation method known on this node.

dfrl_method(M) :-
    (   nonvar(M)
    ->  clause(aggregate_init(M, _, _), _), !
    ;   setof(X, B^Y^Z^clause(aggregate_init(X, Y, Z), B), Ms),
        member(M, Ms)
    ).

%!  dfrl_create(+Node, ?Name, +Plan, +Options) is det.
%
%   Create the agent on Node (not started). Plan is
%   plan(Itinerary, Rounds, RestSeconds, LogFile, Timeout). Options:
%   method(M) (default average), tokens(List).

dfrl_create(Node, Name, Plan, Options) :-
    check_plan(Plan),
    option(method(Method), Options, average),
    must_be(atom, Method),
    option(tokens(Tokens), Options, []),
    (   Tokens == [] -> TokOpts = [] ; TokOpts = [tokens(Tokens)] ),
    agents:agent_create(Name, dfrl_agent:dfrl_tour, TokOpts, Node),
    agent_property(Node, Name, module(M)),
    assertz(M:dfrl_plan(Name, Plan)),
    assertz(M:dfrl_method_of(Name, Method)),
    assertz(M:dfrl_state(Name, state(1, forward, 0, none, [], 0, 0, 0))),
    agents:agent_add_payload(Node, Name, [dfrl_plan/2, dfrl_method_of/2, dfrl_state/2]).

check_plan(plan(Itinerary, Rounds, Rest, Log, Timeout)) :-
    !,
    must_be(list, Itinerary),
    (   Itinerary == [] -> domain_error(non_empty_itinerary, Itinerary) ; true ),
    forall(member(S, Itinerary),
           (   S = stop(H, P, R), atomic(H), integer(P), atom(R)
           ->  true
           ;   throw(error(type_error(stop, S), _))
           )),
    must_be(positive_integer, Rounds),
    must_be(number, Rest),
    must_be(atomic, Log),
    must_be(number, Timeout).
check_plan(Plan) :-
    throw(error(type_error(dfrl_plan, Plan), _)).

		 /*******************************
		 *            HANDLER		*
		 *******************************/

%!  dfrl_tour(+Agent, +Link, +Event) is det.
%
%   The agent's handler: one call per arrival.

dfrl_tour(Agent, Link, main) :-
    dfrl_tour_main(Agent, Link).

%!  dfrl_tour_main(+Agent, +Link) is det.
%
%   What the handler does on arrival (exported, because the handler's
%   clauses are copied into the agent's own module).

dfrl_tour_main(Agent, _Link) :-
    current_node(Node),
    agent_property(Node, Agent, module(M)),
    step(M, Agent).

step(M, Agent) :-
    get_state(M, Agent, state(Round, Phase, Index, Acc, Visited, Hops, Bytes, Start)),
    M:dfrl_plan(Agent, Plan0),
    M:dfrl_method_of(Agent, Method0),
    (   Phase == forward, Index =:= 0
    ->  apply_pending(Plan0, Plan, Method0, Method),
        update(M, dfrl_plan(Agent, Plan)),
        update(M, dfrl_method_of(Agent, Method)),
        get_time(Start1)
    ;   Plan = Plan0, Method = Method0, Start1 = Start
    ),
    Plan = plan(Itinerary, _, _, _, Timeout),
    nth0(Index, Itinerary, stop(_, _, Robot)),
    (   Phase == forward
    ->  forward(Method, Robot, Timeout, Acc, Acc1, Visited, Visited1),
        length(Itinerary, N),
        (   Index =:= N - 1
        ->  finish(Method, Acc1, Final),
            State1 = state(Round, backward, Index, Final, Visited1, Hops, Bytes, Start1),
            put_state(M, Agent, State1),
            step(M, Agent)                      % write into the last robot here
        ;   State1 = state(Round, forward, Index, Acc1, Visited1, Hops, Bytes, Start1),
            go(M, Agent, State1, +1)
        )
    ;   write_back(Robot, Timeout, Acc),
        (   Index =:= 0
        ->  end_round(M, Agent, Round, Hops, Bytes, Start1, Method, Visited)
        ;   go(M, Agent, state(Round, backward, Index, Acc, Visited, Hops, Bytes, Start1), -1)
        )
    ).

%   The aggregate travels packed (fast_term_serialized/2 string): a string
%   is copied, asserted and sent as one block, where a list of 20,000
%   floats costs milliseconds at each of those steps. It is unpacked only
%   where the agent works on it.
get_state(M, Agent, state(R, P, I, Acc, V, H, B, S)) :-
    M:dfrl_state(Agent, state(R, P, I, Packed, V, H, B, S)),
    unpack(Packed, Acc).

put_state(M, Agent, state(R, P, I, Acc, V, H, B, S)) :-
    pack(Acc, Packed),
    update(M, dfrl_state(Agent, state(R, P, I, Packed, V, H, B, S))).

pack(none, none) :- !.
pack(Acc, packed(String)) :-
    fast_term_serialized(Acc, String).

unpack(none, none) :- !.
unpack(packed(String), Acc) :-
    !,
    fast_term_serialized(Acc, String).
unpack(Acc, Acc).

update(M, Fact) :-
    functor(Fact, F, 2),
    arg(1, Fact, Agent),
    functor(Old, F, 2),
    arg(1, Old, Agent),
    retractall(M:Old),
    assertz(M:Fact).

%   Forward: fold this robot's table into the aggregate. A robot that
%   cannot be read is skipped.
forward(Method, Robot, Timeout, Acc0, Acc, Visited0, Visited) :-
    (   catch(read_robot(Method, Robot, Timeout, Table), E,
              ( print_message(warning, E), fail )),
        arg(1, Table, Shape),
        catch(fold(Method, Acc0, Shape, Table, Acc1), E2,
              ( print_message(warning, E2), fail ))
    ->  Acc = Acc1,
        append(Visited0, [Robot], Visited)
    ;   Acc = Acc0,
        Visited = Visited0
    ).

fold(Method, none, Shape, Table, acc(Shape, A)) :-
    !,
    aggregate_init(Method, Table, A).
fold(Method, acc(Shape0, A0), Shape, Table, acc(Shape0, A)) :-
    same_shape(Shape0, Shape),
    aggregate_step(Method, A0, Table, A).

read_robot(Method, Robot, Timeout, Table) :-
    (   method_uses_visits(Method)
    ->  user:get_qtable_and_visits(Robot, qtable(S, V), qtable(S, W), [timeout(Timeout)]),
        Table = qtable_visits(S, V, W)
    ;   user:get_qtable(Robot, Table, [timeout(Timeout)])
    ).

finish(_, none, none) :- !.
finish(Method, acc(Shape, A), qtable(Shape, Values)) :-
    aggregate_final(Method, A, Values).

write_back(_, _, none) :- !.
write_back(Robot, Timeout, Table) :-
    catch(user:set_qtable(Robot, Table, [timeout(Timeout)]), E,
          print_message(warning, E)).

%   Move to the next stop in direction Dir, skipping unreachable ones.
go(M, Agent, State, Dir) :-
    arg(3, State, Index),
    Next is Index + Dir,
    try_stop(M, Agent, State, Next, Dir).

try_stop(M, Agent, State, Next, Dir) :-
    State = state(Round, Phase, Index, Acc, Visited, Hops, Bytes, Start),
    M:dfrl_plan(Agent, plan(Itinerary, _, _, _, _)),
    length(Itinerary, N),
    (   Next >= 0, Next < N
    ->  nth0(Next, Itinerary, stop(H, P, _)),
        carried_bytes(Acc, B),
        Hops1 is Hops + 1,
        Bytes1 is Bytes + B,
        put_state(M, Agent, state(Round, Phase, Next, Acc, Visited,
                                          Hops1, Bytes1, Start)),
        (   catch(move_agent(Agent, (H, P)), E,
                  ( print_message(warning, E), fail ))
        ->  true
        ;   put_state(M, Agent, State),    % still here
            print_message(warning, format("dfrl: skipping stop ~w", [Next])),
            Next1 is Next + Dir,
            try_stop(M, Agent, State, Next1, Dir)
        )
    ;   Phase == forward
    ->  % nothing reachable ahead: finish here and turn back
        M:dfrl_method_of(Agent, Method),
        finish(Method, Acc, Final),
        put_state(M, Agent, state(Round, backward, Index, Final, Visited,
                                          Hops, Bytes, Start)),
        step(M, Agent)
    ;   M:dfrl_method_of(Agent, Method),
        end_round(M, Agent, Round, Hops, Bytes, Start, Method, Visited)
    ).

%   Payload size of the aggregate in bytes: 10 per float in the fast
%   serialisation used on the wire (an estimate, without the clauses).
carried_bytes(qtable(_, V), B) :- !, length(V, N), B is 10 * N.
carried_bytes(acc(_, A), B) :- !, carried_bytes(A, B).
carried_bytes(Acc, B) :-
    (   compound(Acc)
    ->  findall(N, ( arg(_, Acc, L), is_list(L), length(L, N) ), Ns),
        sum_list(Ns, Total),
        B is 10 * Total
    ;   B = 0
    ).

end_round(M, Agent, Round, Hops, Bytes, Start, Method0, Visited) :-
    get_time(End),
    M:dfrl_plan(Agent, plan(Itinerary, Rounds, Rest, Log, _)),
    Method = Method0,
    log_line(Log, round(Round, Start, End, Hops, Bytes, Method, Visited)),
    (   ( Round >= Rounds ; retract(pending(stop)) )
    ->  log_line(Log, finished(Round)),
        purge_agent(Agent)
    ;   Round1 is Round + 1,
        put_state(M, Agent, state(Round1, forward, 0, none, [], 0, 0, 0)),
        (   Rest > 0 -> sleep(Rest) ; true ),
        nth0(0, Itinerary, stop(H, P, _)),
        (   current_node(Node),
            node_property(Node, address(H0:P0)),
            P0 =:= P,
            same_host(H, H0)
        ->  step(M, Agent)
        ;   catch(move_agent(Agent, (H, P)), E,
                  ( log_line(Log, aborted(Round1, E)),
                    print_message(warning, E),
                    purge_agent(Agent) ))
        )
    ).

same_host(H, H) :- !.
same_host(A, B) :- loopback(A), loopback(B).

loopback(localhost).
loopback('127.0.0.1').

log_line(Log, Term) :-
    setup_call_cleanup(
        open(Log, append, Out, [encoding(utf8)]),
        format(Out, '~k.~n', [Term]),
        close(Out)).

apply_pending(Plan0, Plan, Method0, Method) :-
    findall(C, retract(pending(C)), Cs0),
    exclude(==(stop), Cs0, Cs),
    (   memberchk(stop, Cs0) -> assertz(pending(stop)) ; true ),
    foldl(apply_command, Cs, Plan0-Method0, Plan-Method).

apply_command(join(Stop), plan(I0, R, Re, L, T)-M, plan(I, R, Re, L, T)-M) :-
    (   memberchk(Stop, I0) -> I = I0 ; append(I0, [Stop], I) ).
apply_command(method(New), P-Old, P-M) :-
    (   dfrl_method(New)
    ->  M = New
    ;   print_message(warning, format("dfrl: unknown method ~p kept ~p", [New, Old])),
        M = Old
    ).

		 /*******************************
		 *      BUILT-IN METHODS		*
		 *******************************/

aggregate_init(average, qtable(_, V), sum(V, 1)).
aggregate_step(average, sum(A0, N0), qtable(_, V), sum(A, N)) :-
    add_lists(A0, V, A),
    N is N0 + 1.
aggregate_final(average, sum(A, N), Mean) :-
    scale_list(A, N, Mean).

aggregate_init(max, qtable(_, V), max(V)).
aggregate_step(max, max(A0), qtable(_, V), max(A)) :-
    max_lists(A0, V, A).
aggregate_final(max, max(A), A).

method_uses_visits(visit_average).
aggregate_init(visit_average, qtable_visits(_, Q, W), wsum(QW, W, Q, 1)) :-
    mul_lists(Q, W, QW).
aggregate_step(visit_average, wsum(QW0, W0, Q0, N0), qtable_visits(_, Q, W),
               wsum(QW, W1, Q1, N)) :-
    mul_lists(Q, W, QWi),
    add_lists(QW0, QWi, QW),
    add_lists(W0, W, W1),
    add_lists(Q0, Q, Q1),
    N is N0 + 1.
aggregate_final(visit_average, wsum(QW, W, Q, N), Values) :-
    weighted_mean(QW, W, Q, N, Values).

same_shape(S, S) :- !.
same_shape(S, S1) :-
    throw(error(domain_error(table_shape(S), S1), _)).

%!  aggregate_tables(+Method, +Tables, -Table) is det.
%
%   Aggregate a list of qtable(Shape, Values) (or qtable_visits/3 for
%   methods that use visits) in one go, as the agent does over a round.

aggregate_tables(Method, [T|Ts], Table) :-
    arg(1, T, Shape),
    fold(Method, none, Shape, T, A0),
    foldl([X, A1, A2]>>(arg(1, X, S), fold(Method, A1, S, X, A2)), Ts, A0, A),
    finish(Method, A, Table).

%   The element-wise helpers are compiled with the optimise flag, which
%   turns is/2 into virtual-machine arithmetic: 2.5 times faster on
%   20,000-element lists. The flag is restored after them.
:- dynamic saved_optimise/1.
:- current_prolog_flag(optimise, O),
   assertz(saved_optimise(O)),
   set_prolog_flag(optimise, true).

add_lists([], [], []).
add_lists([A|As], [B|Bs], [C|Cs]) :- C is A + B, add_lists(As, Bs, Cs).

mul_lists([], [], []).
mul_lists([A|As], [B|Bs], [C|Cs]) :- C is A * B, mul_lists(As, Bs, Cs).

max_lists([], [], []).
max_lists([A|As], [B|Bs], [C|Cs]) :- C is max(A, B), max_lists(As, Bs, Cs).

scale_list([], _, []).
scale_list([A|As], N, [C|Cs]) :- C is A / N, scale_list(As, N, Cs).

weighted_mean([], [], [], _, []).
weighted_mean([QW|QWs], [W|Ws], [Q|Qs], N, [V|Vs]) :-
    (   W > 0 -> V is QW / W ; V is Q / N ),
    weighted_mean(QWs, Ws, Qs, N, Vs).

:- retract(saved_optimise(O)),
   set_prolog_flag(optimise, O).
