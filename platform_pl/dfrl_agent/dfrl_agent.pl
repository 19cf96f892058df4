:- module(dfrl_agent,
          [ dfrl_tour/3,                % +Agent, +Link, +Event (the handler)
            dfrl_tour_main/2,           % +Agent, +Link
            dfrl_tour_event/3,          % +Agent, +Link, +Event
            dfrl_create/4               % +Node, ?Name, +Plan, +Options
          ]).                           % and dfrl_pending/3, from dfrl_commands
:- use_module('../tartarus').
:- use_module('../agents', [agent_property/3, agent_create/4, agent_add_facts/3]).
:- use_module('../custody', [custody_take_recovered/2]).
:- use_module(dfrl_lease, [lease_arrived/3, lease_check/3, lease_ended/3]).
:- use_module(dfrl_round_state,
              [ new_round/3, get_state/3, put_state/3, pack_state/2, unpack_state/2,
                skip_robot/4 ]).
:- use_module(dfrl_round_log,                   % log_path_ok/1: also as
              [ log_event/2, check_log/1,       % dfrl_agent:log_path_ok/1
                log_path_ok/1, log_text/2 ]).
:- use_module(dfrl_aggregation, [check_method_applies/2]).
:- reexport(dfrl_aggregation,                   % for the agent's users
            [ dfrl_method/1,            % ?Method
              aggregate_tables/3        % +Method, +Tables, -Table
            ]).
:- use_module(dfrl_commands, [queue_command/3]).
:- reexport(dfrl_commands, [dfrl_pending/3]).
:- use_module(dfrl_rounds, [step/2, try_home/4, failed_move/6]).
:- use_module(dfrl_faults, [retire/4, purge_self/1]).
:- use_module(dfrl_tree, [tree_clone_role/3, tree_clone_run/3]).
:- autoload(library(error), [must_be/2, domain_error/2]).
:- autoload(library(lists), [nth0/3, member/2]).
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
(robot_resources.pl: read_robot_table/3, read_robot_tables/4,
write_robot_table/3, read_robot_params/3, write_robot_params/3), which a
robot process implements. Tables are qtable(Shape, Values) with Values a
flat row-major list of floats.

## Tables or parameters

An agent carries Q-tables (`carries(tables)`, the default: its robots
are tabular learners) or parameter vectors (`carries(params)`: function
learners, e.g. DQN; one agent per algorithm, so all its robots are of
one kind), chosen when it is created. In params mode the forward pass
reads each robot's params(Layout, Samples, Values) with
read_robot_params/3 and folds it in (every robot must have the layout of
the first), the backward pass writes params(Layout, Values) with
write_robot_params/3; everything else (itinerary, faults, log, lease) is
the same. A method that does not apply to what the agent carries
(dfrl_aggregation:method_applies/2; of the built-ins only `average`,
as FedAvg, applies to parameters) is refused by dfrl_create/4 with
domain_error(params_method, Method), ignored (and logged) as a control
command method(Name), and, if it got there anyway (a method unknown
where the agent was created), aborts the round at its first stop with
that error in the round's log.

The agent's parts, each loaded with this module wherever it is loaded:
dfrl_rounds.pl (the walk of a round: forward pass, turn, backward pass,
end of round), dfrl_faults.pl (a move timed and skipped, the holder and
the round's lease, rest, retiring), dfrl_round_state.pl (the round state
and its packing), dfrl_payload.pl (what the payload facts say),
dfrl_commands.pl (the queue of control commands), dfrl_move.pl (one
move with retries and a checkpoint), dfrl_lease.pl (the custody
protocol), dfrl_round_log.pl (the JSON-lines log), dfrl_tree.pl (a tree
round by clones) and dfrl_aggregation.pl (the aggregation methods: their
hooks, the built-in methods and running them over a pass). None of them
loads this module. This module holds the handler, creation and the
platform event of control.

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
    queue_command(Node, Agent, Command).

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
