:- module(dfrl_agent,
          [ dfrl_tour/3,                % +Agent, +Link, +Event (the handler)
            dfrl_tour_main/2,           % +Agent, +Link
            dfrl_tour_event/3,          % +Agent, +Link, +Event
            dfrl_create/4,              % +Node, ?Name, +Plan, +Options
            dfrl_pending/3              % ?Node, ?Agent, ?Command
          ]).
:- use_module('../tartarus').
:- use_module('../agents',
              [agent_property/3, agent_create/4, agent_add_facts/3, agent_status/3]).
:- use_module('../custody', [custody_take_recovered/2]).
:- use_module('../agent_bounds', [bounds_park/1]).
:- use_module(dfrl_lease,
              [ lease_arrived/3, lease_check/3, lease_progress/4,
                lease_ended/3, lease_custody/3, lease_adopt/5,
                lease_needs_holder/2, lease_write_gate/2, lease_valid/2,
                copy_owned/2 ]).
:- use_module(dfrl_round_state,
              [ new_round/3, get_state/3, put_state/3, pack_state/2,
                unpack_state/2, replace_fact/2, skip_robot/4, add_retries/3,
                advance_to/3, print_capped_warning/1 ]).
:- use_module(dfrl_round_log,                   % log_path_ok/1: also as
              [ log_round/6, log_control/5, log_event/2, check_log/1,
                log_path_ok/1, log_text/2 ]).   % dfrl_agent:log_path_ok/1
:- use_module(dfrl_move, [move_to_stop/8, skip_after/3]).
:- use_module(dfrl_aggregation,
              [ aggregate_fold/5, aggregate_finish/3, aggregate_fits/2,
                fold_hook/3, method_call/3, item_shape/2, method_applies_to/2,
                check_method_applies/2 ]).
:- reexport(dfrl_aggregation,                   % for the agent's users
            [ dfrl_method/1,            % ?Method
              aggregate_tables/3        % +Method, +Tables, -Table
            ]).
:- use_module('../platform_errors', [message_text/2]).
:- use_module(dfrl_robot_io, [read_robot/5, write_robot/3]).
:- use_module(dfrl_tree, [tree_round/5, tree_clone_role/3, tree_clone_run/3]).
:- autoload(library(error), [must_be/2, domain_error/2]).
:- autoload(library(lists), [nth0/3, append/3, member/2, memberchk/2]).
:- autoload(library(apply), [foldl/4]).
:- autoload(library(option), [option/2, option/3]).

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
  - dfrl_state(Agent, State): where it is in the round, a dict
    `state{round, phase, index, origin, acc, visited, skipped, retries,
    hops, bytes, start, stop}` (acc packed; see dfrl_round_state.pl).
  - dfrl_custody_of(Agent, custody(Epoch, Seq, Holder)): see dfrl_lease.pl.
  - dfrl_retry_of(Agent, retry(Retries, Backoff)).
  - dfrl_skip_after_of(Agent, Seconds): the most all tries of one move
    may take before the stop is skipped (dfrl_move.pl).
  - dfrl_carries_of(Agent, Carried): `tables` or `params` (see below);
    an agent without it carries tables.

## Faults

A move to a stop that fails is tried again Retries times (default 2),
waiting Backoff seconds (default 0.2), then twice that, ...; all tries
together take at most the skip time (option skip_after, default 4 s:
each try's timeouts are cut to what is left of it); then the stop is
skipped for this pass and listed in the round's `skipped` with the error
and how long the agent tried (on the way back a stop that failed this
round is tried once more, without retries, unless it never answered: a
frozen or cut-off stop is not waited for twice in a round). A move
refused because a stale copy of the agent is at the stop has that copy
replaced (dfrl_move.pl) and is tried again. A round starts at the first
stop the agent can reach (`origin`; normally the first of the
itinerary): when the first
stop is down the round starts at the next reachable stop, or where the
agent is, and the backward pass ends there; every round tries the first
stop again, so a stop that comes back is visited again in the next
round. The agent never purges itself because a stop is unreachable; it
aborts only at launch, when no stop at all can be reached.

The agent is not lost with the node it runs or rests on: the stop it came
from (or, where there is none, a stop it asks at its round start and
before its rest) keeps a checkpoint of it under a lease that the agent's
node renews while it lives, and resurrects it (epoch + 1) when that node
stops answering for a lease; a late original that meets the higher epoch
retires. The protocol, and exactly what it guarantees, is in
dfrl_lease.pl. Table reads and writes carry round(N), agent(Name) and
epoch(E) in their options (contract K4).

The agent's handler runs in the agent's own module (see agents.pl), so
the updates of these facts are the agent writing its own state.

Robots are reached through the resource hook of the host process
(robot_resources.pl: get_robot_table/3, get_robot_tables/4,
set_robot_table/3, get_robot_params/3, set_robot_params/3), which a
robot process implements. Tables are qtable(Shape, Values) with Values a
flat row-major list of floats.

## Tables or parameters

An agent carries Q-tables (`carries(tables)`, the default: its robots
are tabular learners) or parameter vectors (`carries(params)`: function
learners, e.g. DQN; one agent per algorithm, so all its robots are of
one kind), chosen when it is created. In params mode the forward pass
reads each robot's params(Layout, Samples, Values) with
get_robot_params/3 and folds it in (every robot must have the layout of
the first), the backward pass writes params(Layout, Values) with
set_robot_params/3; everything else (itinerary, faults, log, lease) is
the same. A method that does not apply to what the agent carries
(dfrl_aggregation:method_applies/2; of the built-ins only `average`,
as FedAvg, applies to parameters) is refused by dfrl_create/4 with
domain_error(params_method, Method), ignored (and logged) as a control
command method(Name), and, if it got there anyway (a method unknown
where the agent was created), aborts the round at its first stop with
that error in the round's log.

The agent's parts, each loaded with this module wherever it is loaded:
dfrl_round_state.pl (the round state and its packing), dfrl_move.pl
(one move with retries and a checkpoint), dfrl_lease.pl (the custody
protocol), dfrl_round_log.pl (the JSON-lines log) and
dfrl_aggregation.pl (the aggregation methods: their hooks, the built-in
methods and running them over a pass). None of them loads this module.

## Round log

The agent appends one JSON object per line to LogFile (a file, or
console(Host, Port, File): posted to a console node): an event per
round, control command, resurrection, retirement and the end of the
tour. The events and their fields are listed in dfrl_round_log.pl,
which writes them.

## Aggregation methods

An aggregation method is a set of clauses of the multifile hooks of
dfrl_aggregation.pl (aggregate_init/3, aggregate_step/4,
aggregate_final/3, method_uses_visits/1), where the hooks, the built-in
methods (`average`, `max`, `visit_average`) and an example of a new
method are documented. This module re-exports dfrl_method/1 and
aggregate_tables/3 from there. A new method is loaded into running
nodes with load_program_at/3 and selected with the control command
method(Name) (example: platform_pl/dfrl_agent/examples/median_method.pl).

## Control

Every node that loads this module declares the platform event
dfrl_control/4. Posting [dfrl_control, platform, Link, Agent, Command]
to the node of the agent's first stop queues Command for Agent (only
for that agent, on that node). The agent takes its queued commands when
it starts its next round there (a round that starts elsewhere, because
the first stop is down, takes those queued where it starts), and logs a
`control` event for each:
join(stop(Host, Port, Robot)) adds a robot at the end of the itinerary,
method(Name) switches the aggregation method (an unknown method is
ignored and the old one kept), stop ends after the current round (a stop
that arrives during a round also ends that round's tour).
*/

:- dynamic
    pending/3,                  % Node, Agent, Command (queued control)
    dfrl_plan/2, dfrl_method_of/2, dfrl_state/2, dfrl_custody_of/2,
    dfrl_retry_of/2, dfrl_carries_of/2, dfrl_skip_after_of/2,
    dfrl_itinerary_of/2.

:- initialization(platform_event(dfrl_agent:dfrl_control/4)).

		 /*******************************
		 *            CONTROL		*
		 *******************************/

%!  dfrl_control(+Platform, +Link, +Agent, +Command) is det.
%
%   The platform event dfrl_control/4: queue Command for Agent on the
%   current node (the node the message was posted to), for the agent's
%   next round start. Commands are checked when the agent takes them.

dfrl_control(platform, _Link, Agent, Command) :-
    must_be(atom, Agent),
    must_be(ground, Command),
    current_node(Node),
    assertz(pending(Node, Agent, Command)).

%!  dfrl_pending(?Node, ?Agent, ?Command) is nondet.
%
%   Command is queued on Node for Agent and not yet taken.

dfrl_pending(Node, Agent, Command) :-
    pending(Node, Agent, Command).

take_commands(Agent, Commands) :-
    current_node(Node),
    findall(C, retract(pending(Node, Agent, C)), Commands).

take_stop(Agent) :-
    current_node(Node),
    retract(pending(Node, Agent, stop)),
    !,
    retractall(pending(Node, Agent, stop)).

%   apply_command(+Carried, +Command, +Plan0-Method0-Stop0, -Plan-Method-Stop,
%                 -Status)
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

		 /*******************************
		 *            CREATE		*
		 *******************************/

%!  dfrl_create(+Node, ?Name, +Plan, +Options) is det.
%
%   Create the agent on Node (not started). Plan is
%   plan(Itinerary, Rounds, RestSeconds, LogFile, Timeout). Options:
%   method(M) (default average), carries(C) (`tables`, the default, or
%   `params`: what the agent aggregates, see "Tables or parameters"),
%   tokens(List), retries(N) (default 2: how often a failed move to a
%   stop is tried again), backoff(S) (default 0.2: the first wait
%   before a retry, doubled each time) and skip_after(S) (default 4: the
%   most seconds all tries of one move take before the stop is skipped
%   for the pass) and itinerary(I) (`chain`, the default, or tree(K):
%   each round a tree of clones of fan-out K >= 2, see dfrl_tree.pl).
%   Start it by moving it to the first
%   stop, or with the event `launch` on Node (it then goes to the first
%   stop it can reach).
%
%   @error type_error(dfrl_plan, Plan), type_error(stop, Stop)
%   @error domain_error(non_empty_itinerary, [])
%   @error domain_error(itinerary, I), domain_error(fanout, K)
%   @error domain_error(params_method, M) if method M, known on this
%   node, does not apply to parameter vectors (table_method for tables).

dfrl_create(Node, Name, Plan, Options) :-
    check_plan(Plan),
    option(method(Method), Options, average),
    must_be(atom, Method),
    option(carries(Carried), Options, tables),
    must_be(oneof([tables, params]), Carried),
    (   dfrl_method(Method)
    ->  check_method_applies(Method, Carried)
    ;   true                            % unknown here: checked at the first stop
    ),
    option(tokens(Tokens), Options, []),
    option(retries(Retries), Options, 2),
    must_be(nonneg, Retries),
    option(backoff(Backoff), Options, 0.2),
    must_be(number, Backoff),
    option(skip_after(SkipAfter), Options, 4),
    must_be(number, SkipAfter),
    (   SkipAfter > 0 -> true ; domain_error(positive_seconds, SkipAfter) ),
    option(itinerary(Kind), Options, chain),
    check_itinerary_kind(Kind),
    (   Tokens == [] -> TokOpts = [] ; TokOpts = [tokens(Tokens)] ),
    % events([]): no peer may post to the tour handler (control comes
    % through the platform event dfrl_control/4, from authenticated peers)
    agent_create(Name, dfrl_agent:dfrl_tour, [events([])|TokOpts], Node),
    new_round(1, 0, State),
    pack_state(State, Packed),
    agent_add_facts(Node, Name, [ dfrl_plan(Name, Plan),
                                  dfrl_method_of(Name, Method),
                                  dfrl_state(Name, Packed),
                                  dfrl_custody_of(Name, custody(1, 0, none)),
                                  dfrl_retry_of(Name, retry(Retries, Backoff)),
                                  dfrl_skip_after_of(Name, SkipAfter),
                                  dfrl_carries_of(Name, Carried),
                                  dfrl_itinerary_of(Name, Kind) ]).

check_itinerary_kind(chain) :- !.
check_itinerary_kind(tree(K)) :-
    !,
    must_be(integer, K),
    (   K >= 2 -> true ; domain_error(fanout, K) ).
check_itinerary_kind(Kind) :-
    domain_error(itinerary, Kind).

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
    check_log(Log),
    must_be(number, Timeout).
check_plan(Plan) :-
    throw(error(type_error(dfrl_plan, Plan), _)).

		 /*******************************
		 *            HANDLER		*
		 *******************************/

%!  dfrl_tour(+Agent, +Link, +Event) is det.
%
%   The agent's handler. Events: `main` (an arrival), `launch` (started
%   on a node that is no stop: go to the first reachable stop),
%   `tree_next` (a tree agent's next round, see next_round/4) and
%   resurrected(Epoch, From, Dead, Resume) (started by dfrl_lease at
%   the stop From after the node Dead was lost with the agent on it).
%   The clause is copied into the agent's own module, so it calls this
%   module explicitly.

dfrl_tour(Agent, Link, Event) :-
    % a qualified goal written here would lose its qualifier when clause/2 reads
    % this clause back (same module): build it, so the copy calls this module
    % from whatever module the agent runs in
    Module = dfrl_agent,
    call(Module:dfrl_tour_event(Agent, Link, Event)).

%!  dfrl_tour_main(+Agent, +Link) is det.
%
%   What the handler does on arrival: dfrl_tour_event(Agent, Link, main).

dfrl_tour_main(Agent, Link) :-
    dfrl_tour_event(Agent, Link, main).

%!  dfrl_tour_event(+Agent, +Link, +Event) is det.
%
%   The body of the handler (exported, because the handler's clauses
%   run in the agent's own module).

dfrl_tour_event(Agent, _Link, Event) :-
    current_node(Node),
    agent_property(Node, Agent, module(M)),
    (   Event == main,
        tree_clone_role(M, Agent, Role)
    ->  tree_clone_run(M, Agent, Role)          % a clone of a tree round
    ;   event(Event, Node, M, Agent)
    ).

event(main, Node, M, Agent) :-
    (   custody_take_recovered(Node, Agent)
    ->  % restarted from this node's store: a holder may have resurrected
        % it elsewhere meanwhile (then this copy is stale and retires)
        lease_check(Node, Agent, Verdict)
    ;   lease_arrived(Node, Agent, Verdict)
    ),
    (   Verdict = superseded(E2)
    ->  retire(Node, M, Agent, E2)
    ;   step(M, Agent)
    ).
event(tree_next, _, M, Agent) :-
    get_state(M, Agent, S),
    try_home(M, Agent, S, 0).
event(launch, _, M, Agent) :-
    get_state(M, Agent, S0),
    put_dict(_{phase:home, index: -1}, S0, S),
    put_state(M, Agent, S),
    try_home(M, Agent, S, 0).
event(resurrected(Epoch, From, Dead, resume(Packed, Next, Progress0)), Node, M,
      Agent) :-
    unpack_state(Packed, S0),
    (   Progress0 = fresh(W)            % the old copy may still be in its round:
    ->  get_dict(round, S0, R00),       % start the next one no stop has written
        R0 is max(R00, W),              % (lease_watch:resume_point/6)
        Progress = round_done(R0, false)
    ;   Progress = Progress0
    ),
    M:dfrl_plan(Agent, plan(Itinerary, _, _, Log, _)),
    format(string(Why), "lost with its node ~w; resurrected at ~w with epoch ~w",
           [Dead, From, Epoch]),
    nth0(Next, Itinerary, stop(_, _, DeadRobot)),
    log_text(From, FromText),
    log_text(Dead, DeadText),
    get_time(Now),
    Event = _{event:resurrected, agent:Agent, epoch:Epoch, from:FromText,
              dead:DeadText, time:Now},
    (   Progress = round_done(Round, true)
    ->  % the tour had ended there: end it here
        log_event(Log, Event.put(round, Round)),
        log_event(Log, _{event:finished, agent:Agent, round:Round}),
        lease_ended(Node, Agent, finished),
        purge_self(Agent)
    ;   Progress = round_done(Round0, false)
    ->  Round is Round0 + 1,
        log_event(Log, Event.put(round, Round)),
        get_dict(index, S0, At),
        new_round(Round, At, S1),
        put_dict(phase, S1, home, S2),
        skip_robot(DeadRobot, reason(Why), S2, S),
        put_state(M, Agent, S),
        try_home(M, Agent, S, 0)
    ;   get_dict(round, S0, Round),
        log_event(Log, Event.put(round, Round)),
        failed_move(M, Agent, S0, Next, reason(Why), 0)
    ).

step(M, Agent) :-
    get_state(M, Agent, S00),
    (   get_dict(phase, S00, home)
    ->  get_dict(index, S00, Here),
        put_dict(_{phase:forward, origin:Here}, S00, S0)
    ;   S0 = S00
    ),
    get_dict(phase, S0, Phase),
    get_dict(index, S0, Index),
    get_dict(origin, S0, Origin),
    (   Phase == forward, Index =:= Origin
    ->  (   round_gate(M, Agent, S0)
        ->  start_round(M, Agent, S0, S1),
            step_work(M, Agent, S1)
        ;   true                        % it retired
        )
    ;   step_work(M, Agent, S0)
    ).

step_work(M, Agent, S1) :-
    get_dict(phase, S1, Phase),
    get_dict(index, S1, Index),
    get_dict(origin, S1, Origin),
    M:dfrl_plan(Agent, plan(Itinerary, _, _, _, Timeout)),
    M:dfrl_method_of(Agent, Method),
    carried(M, Agent, Carried),
    nth0(Index, Itinerary, stop(_, _, Robot)),
    robot_options(Agent, S1, Timeout, Options),
    (   Phase == forward,
        itinerary_kind(M, Agent, tree(K))
    ->  tree_round(M, Agent, K, S1, S2a),
        (   tree_fallback(M, Agent, Method, Carried, K, S1, S2a, S2)
        ->  true
        ;   S2 = S2a
        ),
        end_round(M, Agent, S2.put(itinerary, tree(K)))
    ;   Phase == forward
    ->  forward(Carried-Method, Robot, Options, S1, S2),
        length(Itinerary, N),
        (   restart_with_fallback(M, Agent, Method, Carried, S2)
        ->  true
        ;   Index =:= N - 1
        ->  turn_back(M, Agent, Method, S2)     % writes the last robot here
        ;   go(M, Agent, S2, +1)
        )
    ;   write_back(Robot, Options, S1, S2),
        (   Index =:= Origin
        ->  end_round(M, Agent, S2)
        ;   go(M, Agent, S2, -1)
        )
    ).

%   Contract K4: where a table read or write comes from.
robot_options(Agent, S, Timeout, [timeout(Timeout), round(Round), agent(Agent),
                                  epoch(Epoch)]) :-
    get_dict(round, S, Round),
    current_node(Node),
    lease_custody(Node, Agent, custody(Epoch, _, _)).

%   The agent's itinerary: chain (also for an agent created before trees
%   existed) or tree(K).
itinerary_kind(M, Agent, Kind) :-
    (   catch(M:dfrl_itinerary_of(Agent, K), error(existence_error(_, _), _), fail)
    ->  Kind = K
    ;   Kind = chain
    ).

%   What the agent carries: tables or params (an agent created before
%   params existed has no dfrl_carries_of/2 fact: tables).
carried(M, Agent, Carried) :-
    (   catch(M:dfrl_carries_of(Agent, C), error(existence_error(_, _), _), fail)
    ->  Carried = C
    ;   Carried = tables
    ).

%   At the first stop of the round, before the first table is read: take
%   the queued control commands and note the start time. A method that
%   does not apply to what the agent carries (possible only for a method
%   unknown where the agent was created) aborts the round.
start_round(M, Agent, S0, S) :-
    M:dfrl_plan(Agent, Plan0),
    M:dfrl_method_of(Agent, Method0),
    carried(M, Agent, Carried),
    get_dict(round, S0, Round),
    get_dict(stop, S0, Stop0),
    arg(4, Plan0, Log),
    take_commands(Agent, Commands),
    foldl(take_command(Log, Agent, Round, Carried), Commands,
          Plan0-Method0-Stop0, Plan-Method-Stop),
    replace_fact(M, dfrl_plan(Agent, Plan)),
    replace_fact(M, dfrl_method_of(Agent, Method)),
    (   get_dict(start, S0, Start0), Start0 > 0
    ->  Start = Start0                  % started again after a fallback
    ;   get_time(Start)
    ),
    put_dict(_{start:Start, stop:Stop}, S0, S1),
    (   dfrl_method(Method),
        \+ method_applies_to(Method, Carried)
    ->  catch(check_method_applies(Method, Carried), E, true),
        message_text(E, Text),
        method_failed(error(Text), S1, S)
    ;   S = S1
    ).

take_command(Log, Agent, Round, Carried, Command, Acc0, Acc) :-
    apply_command(Carried, Command, Acc0, Acc, Status),
    log_control(Log, Agent, Round, Command, Status).

turn_back(M, Agent, Method, S0) :-
    get_dict(acc, S0, Acc),
    method_call(aggregate_finish(Method, Acc, Final0), aggregate_final(Method), Result),
    (   Result == ok,
        alone(M, Agent, S0)
    ->  S1 = S0,                        % nothing federated: nothing written
        Final = none
    ;   Result == ok
    ->  S1 = S0,
        Final = Final0
    ;   method_failed(Result, S0, S1),
        Final = none
    ),
    carried(M, Agent, Carried),
    (   restart_with_fallback(M, Agent, Method, Carried, S1)
    ->  true
    ;   put_dict(_{phase:backward, acc:Final}, S1, S),
        put_state(M, Agent, S),
        step(M, Agent)
    ).

%   A round that read no robot but its own, of an itinerary of several,
%   federated nothing: it writes nothing (not even that robot's own table
%   back), so that a copy cut off from every other stop writes nothing
%   in a round that a resurrected copy may run too (lease_watch.pl).
alone(M, Agent, S) :-
    get_dict(visited, S, [_]),
    M:dfrl_plan(Agent, plan(Itinerary, _, _, _, _)),
    Itinerary = [_, _|_].

%   A method that failed in the forward pass (State has an error) is
%   replaced, for this round already, by the method the next round would
%   fall back to (next_method/5): the round starts again from its first
%   stop with it, so every robot still gets a table and is released. The
%   failure stays on record (the state's `fallback`, logged with the
%   round: the failed method and its error). Once a round: a fallback
%   that fails too, or a move back to the first stop that fails, aborts
%   the round as before (no table written). A tree round is run again
%   with the fallback (tree_fallback/8).
restart_with_fallback(M, Agent, Method, Carried, S0) :-
    get_dict(error, S0, Error),
    \+ get_dict(fallback, S0, _),
    \+ get_dict(fallback_tried, S0, _),
    next_method(Method, Carried, S0, Next, _),
    Next \== Method,
    get_dict(round, S0, Round),
    print_message(warning,
                  format("dfrl: ~w round ~w: method ~w failed (~w); the round starts \c
                          again from its first stop with ~w", [Agent, Round, Method,
                                                               Error, Next])),
    del_dict(error, S0, _, S1),
    put_dict(_{acc:none, visited:[], phase:forward,
               fallback:failed(Method, Error)}, S1, S2),
    replace_fact(M, dfrl_method_of(Agent, Next)),
    M:dfrl_plan(Agent, plan(Itinerary, _, _, Log, _)),
    log_control(Log, Agent, Round, fallback(Method, Next), applied),
    get_dict(origin, S2, Origin),
    get_dict(index, S2, Index),
    (   Index =:= Origin
    ->  put_state(M, Agent, S2),
        step(M, Agent)
    ;   nth0(Origin, Itinerary, Stop),
        advance_to(Origin, S2, S3),
        timed_move(M, Agent, S2, S3, Stop, Origin, policy, Result),
        (   Result = failed(E, _, _)
        ->  % the agent stays here: the round goes on without a table, as before
            print_message(warning, format("dfrl: ~w round ~w: no way back to the first \c
                                           stop (~w); round aborted", [Agent, Round, E])),
            replace_fact(M, dfrl_method_of(Agent, Method)),
            put_dict(fallback_tried, S0, true, S4),
            put_state(M, Agent, S4),
            (   get_dict(phase, S4, forward), \+ last_stop(M, Agent, Index)
            ->  go(M, Agent, S4, +1)
            ;   put_dict(_{phase:backward, acc:none}, S4, S5),
                put_state(M, Agent, S5),
                step(M, Agent)
            )
        ;   true
        )
    ).

%   A tree round whose method failed is run again at once with the method
%   it falls back to (as a chain round, restart_with_fallback/5): its
%   copies read and write every robot again; the hops of both count.
tree_fallback(M, Agent, Method, Carried, K, S1, S2, S) :-
    get_dict(error, S2, Error),
    \+ get_dict(fallback, S1, _),
    next_method(Method, Carried, S2, Next, _),
    Next \== Method,
    get_dict(round, S1, Round),
    print_message(warning,
                  format("dfrl: ~w round ~w: method ~w failed (~w); the tree round runs \c
                          again with ~w", [Agent, Round, Method, Error, Next])),
    replace_fact(M, dfrl_method_of(Agent, Next)),
    M:dfrl_plan(Agent, plan(_, _, _, Log, _)),
    log_control(Log, Agent, Round, fallback(Method, Next), applied),
    get_dict(hops, S2, Hops),
    get_dict(bytes, S2, Bytes),
    get_dict(retries, S2, Retries),
    (   del_dict(error, S1, _, S1a)         % the method did not apply at all
    ->  true
    ;   S1a = S1
    ),
    put_dict(_{hops:Hops, bytes:Bytes, retries:Retries,
               fallback:failed(Method, Error)}, S1a, S1b),
    tree_round(M, Agent, K, S1b, S).

last_stop(M, Agent, Index) :-
    M:dfrl_plan(Agent, plan(Itinerary, _, _, _, _)),
    length(Itinerary, N),
    Index =:= N - 1.

%   Forward: fold this robot's table into the aggregate. A robot that
%   cannot be read (or whose table does not fit) is skipped. A method
%   whose hook fails or throws aborts the round: the error is kept in the
%   state (logged with the round), the aggregate is dropped so that no
%   robot is written, and no further robot is read this round.
forward(_, _, _, S0, S) :-
    get_dict(error, S0, _),
    !,
    S = S0.
forward(Carried-Method, Robot, Options, S0, S) :-
    get_dict(acc, S0, Acc0),
    (   catch(( read_robot(Carried, Method, Robot, Options, Table),
                item_shape(Table, Shape),
                aggregate_fits(Acc0, Shape)
              ),
              E, true)
    ->  (   var(E)
        ->  fold_hook(Acc0, Method, Hook),
            method_call(aggregate_fold(Method, Acc0, Shape, Table, Acc1), Hook, Result),
            (   Result == ok
            ->  get_dict(visited, S0, V0),
                append(V0, [Robot], V),
                put_dict(_{acc:Acc1, visited:V}, S0, S)
            ;   method_failed(Result, S0, S)
            )
        ;   print_capped_warning(E),
            skip_robot(Robot, E, S0, S)
        )
    ;   skip_robot(Robot, failed(read_robot(Robot)), S0, S)
    ).

method_failed(error(Error), S0, S) :-
    print_message(error, format("dfrl: aggregation method: ~w; round aborted, \c
                                 no table is written", [Error])),
    put_dict(_{error:Error, acc:none}, S0, S).

write_back(Robot, Options, S0, S) :-
    get_dict(acc, S0, Table),
    current_node(Node),
    memberchk(agent(Agent), Options),
    (   Table == none
    ->  S = S0
    ;   \+ lease_write_gate(Node, Agent)
    ->  skip_robot(Robot, reason("not written: the agent's lease could not be renewed \c
                                  (fenced)"), S0, S)
    ;   catch(write_robot(Table, Robot, Options), E, true),
        (   var(E)
        ->  S = S0
        ;   print_capped_warning(E),
            skip_robot(Robot, E, S0, S)
        )
    ).

%   Move to the next stop in direction Dir, skipping unreachable ones.
go(M, Agent, S, Dir) :-
    get_dict(index, S, Index),
    Next is Index + Dir,
    try_stop(M, Agent, S, Next, Dir).

%   A forward pass goes up to the last stop, a backward pass down to the
%   stop where the round started (origin).
try_stop(M, Agent, S0, Next, _Dir) :-
    M:dfrl_plan(Agent, plan(Itinerary, _, _, _, _)),
    length(Itinerary, N),
    get_dict(phase, S0, Phase),
    get_dict(origin, S0, Origin),
    (   Next >= Origin, Next < N
    ->  nth0(Next, Itinerary, Stop),
        advance_to(Next, S0, S1),
        Stop = stop(_, _, Robot),
        get_dict(skipped, S0, Skipped),
        (   Phase == backward, memberchk(skip(Robot, _), Skipped)
        ->  Tries = once                % it failed this round already
        ;   Tries = policy
        ),
        (   Phase == backward, unanswered(S0, Robot)
        ->  % no answer in its skip time this round: not waited for again
            failed_move(M, Agent, S0, Next, reason("no answer earlier this round"), 0)
        ;   timed_move(M, Agent, S0, S1, Stop, Next, Tries, Result),
            (   Result = failed(E, Retries, Silent)
            ->  note_unanswered(Silent, Robot, S0, S0a),
                failed_move(M, Agent, S0a, Next, E, Retries)
            ;   true
            )
        )
    ;   Phase == forward
    ->  % nothing reachable ahead: finish here and turn back
        M:dfrl_method_of(Agent, Method),
        turn_back(M, Agent, Method, S0)
    ;   end_round(M, Agent, S0)
    ).

%   move_to_stop/8; a failure is failed(reason(Text), Retries, Silent):
%   Text is the error's text and how long the agent tried before it
%   skipped the stop, Silent is true if the stop never answered (a
%   timeout: frozen or cut off), so that the backward pass does not wait
%   for it again.
timed_move(M, Agent, S0, S1, Stop, Index, Tries, Result) :-
    get_time(T0),
    move_to_stop(M, Agent, S0, S1, Stop, Index, Tries, Result0),
    (   Result0 = failed(E, Retries)
    ->  get_time(T1),
        Waited is T1 - T0,
        skip_after(M, Agent, Bound),
        message_text(E, Text0),
        format(string(Text), "~w (skipped after ~2f s; skip_after ~w s)",
               [Text0, Waited, Bound]),
        print_message(warning, format("dfrl: skipping stop ~w: ~w", [Index, Text])),
        (   E = error(transport_error(_, timeout(_)), _)
        ->  Silent = true
        ;   Silent = false
        ),
        Result = failed(reason(Text), Retries, Silent)
    ;   Result = Result0
    ).

unanswered(S, Robot) :-
    get_dict(unanswered, S, Robots),
    memberchk(Robot, Robots).

note_unanswered(false, _, S, S).
note_unanswered(true, Robot, S0, S) :-
    (   get_dict(unanswered, S0, Rs) -> true ; Rs = [] ),
    put_dict(unanswered, S0, [Robot|Rs], S).

%   Find the agent a holder if it has none (at its first stop after a
%   launch, after a resurrection, or its holder lost its checkpoint)
%   before it works or rests here: another stop of the itinerary keeps a
%   checkpoint of it under a lease, which resurrects it if this node
%   stops answering (dfrl_lease:lease_adopt/5). The stops after this one
%   are asked first, then those before; robots skipped this round are
%   not asked. A resurrection there starts this round again from the
%   holder, without this stop.
ensure_holder(M, Agent, S) :-
    current_node(Node),
    (   lease_needs_holder(Node, Agent)
    ->  M:dfrl_plan(Agent, plan(Itinerary, _, _, _, _)),
        get_dict(index, S, Here),
        get_dict(round, S, Round),
        get_dict(skipped, S, Skipped),
        length(Itinerary, N),
        Last is N - 1,
        (   Here >= 0, nth0(Here, Itinerary, stop(H, P, _))
        ->  Round0 is Round - 1,
            findall(Addr-resume(Packed, Here, round_done(Round0, false)),
                    ( ( between(Here, Last, J) ; between(0, Here, J) ),
                      J =\= Here,
                      nth0(J, Itinerary, stop(HJ, PJ, RJ)),
                      \+ memberchk(skip(RJ, _), Skipped),
                      Addr = HJ:PJ,
                      new_round(Round, J, SJ),
                      pack_state(SJ, Packed)
                    ),
                    Offers0),
            first_n(3, Offers0, Offers),
            lease_adopt(Node, Agent, H:P, Offers, Holder),
            (   Holder == none, Offers \== []
            ->  print_message(warning,
                              format("dfrl: ~w has no holder at ~w: no other stop took its checkpoint",
                                     [Agent, H:P]))
            ;   true
            )
        ;   true
        )
    ;   true
    ).

%   A round starts only under a lease that its holder knows covers this
%   round (progress started(Round), one request a round): a holder that
%   resurrects the agent where the old copy may still run then starts
%   the round after it, never this one again. Without it (the holder cut
%   off or frozen, and no other stop takes a checkpoint), the agent
%   waits, parked, and tries again every half second, up to 900 s; a
%   higher epoch met meanwhile retires it (and the gate fails).
round_gate(M, Agent, S) :-
    current_node(Node),
    get_time(T0),
    round_gate(Node, M, Agent, S, T0, 0).

round_gate(Node, M, Agent, S, T0, Tries) :-
    copy_owned(Node, Agent),            % not replaced while it waited
    ensure_holder(M, Agent, S),
    get_dict(round, S, Round),
    lease_progress(Node, Agent, started(Round), Verdict),
    (   Verdict = superseded(E2)
    ->  retire(Node, M, Agent, E2),
        fail
    ;   Tries =:= 0,
        \+ lease_valid(Node, Agent),
        lease_needs_holder(Node, Agent)
    ->  round_gate(Node, M, Agent, S, T0, 1)    % its holder was lost just now
    ;   lease_valid(Node, Agent)
    ->  true
    ;   get_time(Now),
        Now - T0 > 900
    ->  throw(error(timeout_error(round_gate, Agent),
                    context(dfrl_agent:round_gate/3,
                            'no lease for 900 s: its holder and every other stop are silent')))
    ;   (   Tries =< 1
        ->  print_message(warning,
                          format("dfrl: ~w waits to start round ~w: its lease cannot be renewed \c
                                  and no other stop holds it", [Agent, Round]))
        ;   true
        ),
        bounds_park(sleep(0.5)),
        lease_arrived(Node, Agent, V),
        (   V = superseded(E3)
        ->  retire(Node, M, Agent, E3),
            fail
        ;   Tries1 is Tries + 2,
            round_gate(Node, M, Agent, S, T0, Tries1)
        )
    ).

first_n(N, L, Prefix) :-
    length(L, Len),
    (   Len =< N -> Prefix = L ; length(Prefix, N), append(Prefix, _, L) ).

%   The move to stop Next failed (or the agent was lost there and is
%   resurrected from the state S0 it had before): skip its robot and go
%   on as the phase says.
failed_move(M, Agent, S0, Next, Error, Retries) :-
    M:dfrl_plan(Agent, plan(Itinerary, _, _, _, _)),
    nth0(Next, Itinerary, stop(_, _, Robot)),
    skip_robot(Robot, Error, S0, S1),
    add_retries(Retries, S1, S),
    put_state(M, Agent, S),
    get_dict(phase, S, Phase),
    (   Phase == forward
    ->  Next1 is Next + 1,
        try_stop(M, Agent, S, Next1, +1)
    ;   Phase == backward
    ->  Next1 is Next - 1,
        try_stop(M, Agent, S, Next1, -1)
    ;   Next1 is Next + 1,
        try_home(M, Agent, S, Next1)
    ).

%   Find where the round starts (phase home): the first stop before the
%   one the agent is at (index At; -1 at launch, on a node that is no
%   stop) that it can reach, else where it is. Robots already skipped in
%   this round (a stop known to be lost) are not tried again.
try_home(M, Agent, S0, J) :-
    M:dfrl_plan(Agent, plan(Itinerary, _, _, Log, _)),
    length(Itinerary, N),
    get_dict(index, S0, At),
    (   At >= 0 -> Limit = At ; Limit = N ),
    (   J < Limit
    ->  nth0(J, Itinerary, Stop),
        Stop = stop(_, _, Robot),
        get_dict(skipped, S0, Skipped),
        (   memberchk(skip(Robot, _), Skipped)
        ->  J1 is J + 1,
            try_home(M, Agent, S0, J1)
        ;   advance_to(J, S0, S1),
            timed_move(M, Agent, S0, S1, Stop, J, policy, Result),
            (   Result = failed(E, Retries, _)
            ->  failed_move(M, Agent, S0, J, E, Retries)
            ;   true
            )
        )
    ;   At >= 0
    ->  put_dict(_{phase:forward, origin:At}, S0, S),
        put_state(M, Agent, S),
        step(M, Agent)
    ;   get_dict(round, S0, Round),
        log_event(Log, _{event:aborted, agent:Agent, round:Round,
                         error:"no stop of the itinerary can be reached"}),
        purge_self(Agent)
    ).

%   The round ends where it started (or where the backward pass stopped).
%   The holder hears of it first (a resurrection then starts the next
%   round); an agent that learns there that it was superseded retires
%   without logging. Then the next round starts at the first reachable
%   stop, after the rest.
end_round(M, Agent, S) :-
    current_node(Node),
    get_time(End),
    M:dfrl_plan(Agent, Plan),
    Plan = plan(_, Rounds, Rest, Log, _),
    M:dfrl_method_of(Agent, Method),
    carried(M, Agent, Carried),
    next_method(Method, Carried, S, Next, Good),
    get_dict(round, S, Round),
    (   (   Round >= Rounds
        ->  Why = none
        ;   get_dict(stop, S, true)
        ->  Why = none
        ;   take_stop(Agent)
        ->  Why = stop
        )
    ->  Last = true
    ;   Last = false
    ),
    lease_progress(Node, Agent,
                   round_done(Round, Last, [dfrl_plan(Agent, Plan),
                                            dfrl_method_of(Agent, Next)]),
                   Verdict),
    (   Verdict = superseded(E2)
    ->  retire(Node, M, Agent, E2)
    ;   lease_custody(Node, Agent, custody(Epoch, _, _)),
        log_round(Log, Agent, Method, Epoch, End, S),
        (   Next == Method
        ->  true
        ;   replace_fact(M, dfrl_method_of(Agent, Next)),
            log_control(Log, Agent, Round, fallback(Method, Next), applied)
        ),
        (   Last == true
        ->  (   Why == stop -> log_control(Log, Agent, Round, stop, applied) ; true ),
            take_commands(Agent, Left),             % too late for them
            forall(member(C, Left),
                   log_control(Log, Agent, Round, C,
                               ignored("the agent has finished its tour"))),
            lease_ended(Node, Agent, finished),
            log_event(Log, _{event:finished, agent:Agent, round:Round}),
            purge_self(Agent)
        ;   Round1 is Round + 1,
            get_dict(index, S, At),
            new_round(Round1, At, S1a),
            put_dict(_{phase:home, good:Good}, S1a, S1),
            put_state(M, Agent, S1),
            ensure_holder(M, Agent, S1),
            rest(Node, Agent, Rest, Verdict1),
            (   Verdict1 = superseded(E3)
            ->  retire(Node, M, Agent, E3)
            ;   next_round(Node, M, Agent, S1)
            )
        )
    ).

%   Start the next round at the first reachable stop. A tree agent stays
%   on its node (dfrl_tree.pl), so it starts the round in a new handler
%   call (event tree_next): a handler call may take agent_cpu_limit
%   seconds of CPU (agent_bounds.pl), a round each, not a whole tour.
next_round(Node, M, Agent, S) :-
    (   itinerary_kind(M, Agent, tree(_))
    ->  node_property(Node, link(Link)),
        agents:agent_execute(Node, Agent, Link, tree_next)
    ;   try_home(M, Agent, S, 0)
    ).

%   next_method(+Method, +Carried, +State, -Next, -Good)
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

%   Rest between rounds, in short slices, watching for a higher epoch;
%   then ask the holder (a long pause may have made it resurrect us).
%   The rest is parked (agent_bounds:bounds_park/1): it holds no run slot
%   of the node and counts against agent_idle_limit (600 s by default,
%   with the robot waits of the same handler call), not agent_wall_limit.
rest(Node, Agent, Rest, Verdict) :-
    (   Rest > 0
    ->  get_time(T0),
        Until is T0 + Rest,
        bounds_park(rest_until(Node, Agent, Until, Verdict0)),
        (   Verdict0 == ok
        ->  lease_check(Node, Agent, Verdict)
        ;   Verdict = Verdict0
        )
    ;   Verdict = ok
    ).

rest_until(Node, Agent, Until, Verdict) :-
    get_time(Now),
    (   Now >= Until
    ->  Verdict = ok
    ;   Slice is min(0.2, Until - Now),
        sleep(Slice),
        lease_arrived(Node, Agent, V),
        (   V == ok
        ->  rest_until(Node, Agent, Until, Verdict)
        ;   Verdict = V
        )
    ).

%   The agent ends here: purge the copy that runs this thread, and only
%   that one. A stale copy may have been replaced meanwhile by a newer
%   one that arrived under the same name (dfrl_lease: supersede); that
%   one is not this thread's to purge.
purge_self(Agent) :-
    current_node(Node),
    thread_self(Me),
    (   agent_status(Node, Agent, running(Me))
    ->  purge_agent(Agent)
    ;   true
    ).

%   A copy that met a higher epoch stops, says so and lets its holder go.
retire(Node, M, Agent, Epoch2) :-
    copy_owned(Node, Agent),
    lease_custody(Node, Agent, custody(Epoch, _, _)),
    M:dfrl_plan(Agent, plan(_, _, _, Log, _)),
    get_state(M, Agent, S),
    get_dict(round, S, Round),
    print_message(warning,
                  format("dfrl: ~w (epoch ~w) superseded by epoch ~w; retires",
                         [Agent, Epoch, Epoch2])),
    log_event(Log, _{event:superseded, agent:Agent, round:Round, epoch:Epoch,
                     by:Epoch2}),
    lease_ended(Node, Agent, superseded),
    purge_self(Agent).
