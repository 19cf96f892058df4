:- module(dfrl_rounds,
          [ step/2,                     % +Module, +Agent
            go/4,                       % +Module, +Agent, +State, +Dir
            try_home/4,                 % +Module, +Agent, +State, +Index
            failed_move/6               % +Module, +Agent, +State, +Index, +Error, +Retries
          ]).
:- use_module('../tartarus', [current_node/1, node_property/2]).
:- use_module('../agents', [agent_execute/4]).
:- use_module(dfrl_lease, [lease_progress/4, lease_ended/3, lease_custody/3,
                           lease_write_gate/2]).
:- use_module(dfrl_round_state,
              [ new_round/3, get_state/3, put_state/3, replace_fact/2, skip_robot/4,
                add_retries/3, advance_to/3, method_failed/3, print_capped_warning/1,
                fold_item/6 ]).
:- use_module(dfrl_round_log, [log_round/6, log_control/5, log_event/2]).
:- use_module(dfrl_commands, [take_commands/2, take_stop/1, apply_command/5]).
:- use_module(dfrl_payload,
              [ robot_options/4, itinerary_kind/3, carried/3, alone/3, last_stop/3,
                next_method/5 ]).
:- use_module(dfrl_faults,
              [ timed_move/8, unanswered/2, note_unanswered/4, ensure_holder/3,
                round_gate/3, rest/4, retire/4, purge_self/1 ]).
:- use_module(dfrl_aggregation,
              [ aggregate_fold/5, aggregate_finish/3, aggregate_fits/2, fold_hook/3,
                method_call/3, item_shape/2, method_applies_to/2, check_method_applies/2,
                dfrl_method/1 ]).
:- use_module('../platform_errors', [message_text/2]).
:- use_module(dfrl_robot_io, [read_robot/5, write_robot/3]).
:- use_module(dfrl_tree, [tree_round/5, tree_fallback/6]).
:- autoload(library(lists), [nth0/3, append/3, member/2, memberchk/2]).
:- autoload(library(apply), [foldl/4]).

/** <module> The rounds of the dFRL agent: its walk over the itinerary

What the dFRL agent (dfrl_agent.pl) does at each stop of a round:
step/2 is the agent's work on arrival. At the round's first stop it
takes its queued commands (dfrl_commands.pl) once the round's lease is
granted (dfrl_faults:round_gate/3); on the way out it reads the robot
and folds its table into the aggregate (forward pass), at the last stop
it finishes the aggregate and turns back (turn_back/4), and on the way
back it writes it into each robot (backward pass); at the first stop
again it logs the round, rests and starts the next one (end_round/3).
A method that fails is replaced by its fallback within the round.
go/4 and try_home/4 choose the next stop, skipping those that cannot be
reached; what a failed move, a lost holder or a higher epoch mean is
dfrl_faults.pl's. The round state is the dict of dfrl_round_state.pl.
*/

%!  step(+Module, +Agent) is det.
%
%   The agent's work at the stop it is at, in the phase and at the
%   index of its round state.

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
        (   tree_fallback(M, Agent, Method, S1, S2a, S2)
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

%   A method that failed in the forward pass (State has an error) is
%   replaced, for this round already, by the method the next round would
%   fall back to (next_method/5): the round starts again from its first
%   stop with it, so every robot still gets a table and is released. The
%   failure stays on record (the state's `fallback`, logged with the
%   round: the failed method and its error). Once a round: a fallback
%   that fails too, or a move back to the first stop that fails, aborts
%   the round as before (no table written). A tree round is run again
%   with the fallback (dfrl_tree:tree_fallback/6).
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
        ->  fold_item(Method, Robot, Shape, Table, S0, S)
        ;   print_capped_warning(E),
            skip_robot(Robot, E, S0, S)
        )
    ;   skip_robot(Robot, failed(read_robot(Robot)), S0, S)
    ).

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

%!  go(+Module, +Agent, +State, +Dir) is det.
%
%   Move to the next stop in direction Dir (+1 or -1), skipping
%   unreachable ones.

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

%!  failed_move(+Module, +Agent, +State, +Index, +Error, +Retries) is det.
%
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

%!  try_home(+Module, +Agent, +State, +Index) is det.
%
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
