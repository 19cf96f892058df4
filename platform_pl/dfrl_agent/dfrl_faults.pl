:- module(dfrl_faults,
          [ timed_move/8,               % +M, +Agent, +S0, +S1, +Stop, +Index, +Tries, -Result
            unanswered/2,               % +State, +Robot
            note_unanswered/4,          % +Silent, +Robot, +State0, -State
            ensure_holder/3,            % +Module, +Agent, +State
            round_gate/3,               % +Module, +Agent, +State
            rest/4,                     % +Node, +Agent, +Seconds, -Verdict
            retire/4,                   % +Node, +Module, +Agent, +Epoch
            purge_self/1                % +Agent
          ]).
:- use_module('../tartarus', [current_node/1, purge_agent/1]).
:- use_module('../agents', [agent_status/3]).
:- use_module('../agent_bounds', [bounds_park/1]).
:- use_module('../platform_errors', [message_text/2]).
:- use_module(dfrl_lease,
              [ lease_arrived/3, lease_check/3, lease_progress/4, lease_ended/3,
                lease_custody/3, lease_adopt/5, lease_needs_holder/2, lease_valid/2,
                copy_owned/2 ]).
:- use_module(dfrl_round_state, [new_round/3, get_state/3, pack_state/2]).
:- use_module(dfrl_round_log, [log_event/2]).
:- use_module(dfrl_move, [move_to_stop/8, skip_after/3]).
:- autoload(library(lists), [append/3, memberchk/2]).

/** <module> How the dFRL agent meets faults

The parts of the dFRL agent's walk (dfrl_rounds.pl) that deal with
faults, none of which decides where the walk goes next: a move that
fails within its skip time (timed_move/8, with the stops that never
answered noted so that a round does not wait for them twice); a holder
for the agent's checkpoint (ensure_holder/3) and the lease that must
cover a round before it starts (round_gate/3); the rest between rounds,
watching for a higher epoch (rest/4); and a copy that met a higher
epoch retiring (retire/4). The protocol itself is dfrl_lease.pl's.
*/

%!  timed_move(+Module, +Agent, +State0, +State1, +Stop, +Index, +Tries,
%!             -Result) is det.
%
%   dfrl_move:move_to_stop/8, timed; a failure is failed(reason(Text),
%   Retries, Silent): Text is the error's text and how long the agent
%   tried before it skipped the stop, Silent is true if the stop never
%   answered (a timeout: frozen or cut off), so that the backward pass
%   does not wait for it again. Eight arguments, as move_to_stop/8 (the
%   state the agent leaves, State0, is its checkpoint; State1 is the
%   state it arrives with).

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

%!  unanswered(+State, +Robot) is semidet.
%
%   Robot's stop did not answer a move earlier in the round of State.

unanswered(S, Robot) :-
    get_dict(unanswered, S, Robots),
    memberchk(Robot, Robots).

%!  note_unanswered(+Silent, +Robot, +State0, -State) is det.
%
%   Note in the state that Robot's stop did not answer, if Silent.

note_unanswered(false, _, S, S).
note_unanswered(true, Robot, S0, S) :-
    (   get_dict(unanswered, S0, Rs) -> true ; Rs = [] ),
    put_dict(unanswered, S0, [Robot|Rs], S).

%!  ensure_holder(+Module, +Agent, +State) is det.
%
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
                              format("dfrl: ~w has no holder at ~w: no other stop \c
                                      took its checkpoint", [Agent, H:P]))
            ;   true
            )
        ;   true
        )
    ;   true
    ).

%!  round_gate(+Module, +Agent, +State) is semidet.
%
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

%!  rest(+Node, +Agent, +Seconds, -Verdict) is det.
%
%   Rest between rounds, in short slices, watching for a higher epoch;
%   then ask the holder (a long pause may have made it resurrect us).
%   The rest is parked (agent_bounds:bounds_park/1): it holds no run slot
%   of the node and counts against agent_idle_limit (600 s by default,
%   with the robot waits of the same handler call), not agent_wall_limit.
%   Verdict is ok, or superseded(Epoch) if a higher epoch was met.

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

%!  purge_self(+Agent) is det.
%
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

%!  retire(+Node, +Module, +Agent, +Epoch) is det.
%
%   A copy that met a higher epoch, Epoch, stops, says so and lets its
%   holder go.

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
