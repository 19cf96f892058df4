:- module(lease_requests, []).
:- use_module('../node', [node_property/2, ctx_node/2, ctx_authenticated/1]).
:- use_module('../agents',
              [ agent_exists/2, agent_status/3, agent_remove/2, agent_purge/2,
                agent_module/3 ]).
:- use_module('../tartarus', [with_node/2]).
:- use_module(dfrl_round_log, [log_event/2]).
:- use_module(dfrl_round_state, [get_state/3]).
:- use_module('../code_safety', [check_agent_record/1]).
:- use_module('../custody', [with_custody/2, custody_unstage/2]).
:- use_module(lease_book).
:- use_module(lease_watch, [ensure_watchdog/0]).
:- autoload(library(lists), [member/2, append/3, last/2, max_list/2]).
:- autoload(library(apply), [foldl/4]).

/** <module> The custody requests a stop serves for the dFRL agent's leases

The other side of dfrl_lease.pl: what a node answers, as a stop of an
agent's itinerary, to the platform request dfrl_custody(Request) of an
authenticated peer (node:platform_request/4): hold a checkpoint (step 2
of the protocol), release it, note the agent's progress, answer a
probe, an epoch or a request to supersede a stale copy. It exports
nothing; the protocol and its steps are described in dfrl_lease.pl, and
its records are lease_book.pl's.
*/


:- multifile
    node:platform_request/4.

node:platform_request(dfrl_custody(Request), Ctx, Reply, true) :-
    ctx_node(Ctx, Node),
    (   ctx_authenticated(Ctx)
    ->  serve(Request, Node, Answer),
        Reply = ok(Answer)
    ;   node_property(Node, address(Here)),
        Reply = error(error(permission_error(custody, platform, Here), _))
    ).

serve(probe(Agent, E, K), Node, Answer) :-
    probe_answer(Node, Agent, E, K, Answer).
serve(release(Agent, E, K, How), Node, Answer) :-
    (   seen(Node, Agent, E2), E2 > E
    ->  Answer = superseded(E2)
    ;   note_epoch(Node, Agent, E),
        get_time(Now),
        locked(forall(( ckpt(Node, Agent, E1, K1, _, _, _, _, _),
                        E1 =< E, K1 =< K ),
                      ( retractall(ckpt(Node, Agent, E1, K1, _, _, _, _, _)),
                        assertz(gone(Node, Agent, E1, K1, released(How), Now))
                      ))),
        prune_gone(Node, Agent),
        Answer = released
    ).
serve(progress(Agent, E, K, Progress), Node, Answer) :-
    (   \+ progress_ok(Agent, Progress)
    ->  Answer = refused(progress)
    ;   seen(Node, Agent, E2), E2 > E
    ->  Answer = superseded(E2)
    ;   note_epoch(Node, Agent, E),
        lease_s(Node, L),
        get_time(Now),
        Expiry is Now + L,
        locked(( \+ ckpt(Node, Agent, E, K, _, _, _, _, _)
               ->  Answer = unknown
               ;   Progress == alive            % a heartbeat: the expiry only
               ->  set_expiry(Node, Agent, E, K, Expiry),
                   Answer = renewed
               ;   Progress = started(Round)    % a round starts: noted beside it
               ->  set_expiry(Node, Agent, E, K, Expiry),
                   retractall(entered(Node, Agent, E, K, _)),
                   assertz(entered(Node, Agent, E, K, Round)),
                   Answer = renewed
               ;   retract(ckpt(Node, Agent, E, K, Here, Dest, Rec0, Res0, _)),
                   apply_progress(Progress, Here, Rec0, Res0, Rec, Res),
                   assertz(ckpt(Node, Agent, E, K, Here, Dest, Rec, Res,
                                Expiry)),
                   retractall(renewed(Node, Agent, E, K, _)),
                   retractall(entered(Node, Agent, E, K, _)),
                   Answer = renewed
               ))
    ).
serve(epoch(Agent, E), Node, Answer) :-
    (   seen(Node, Agent, E2), E2 > E
    ->  Answer = superseded(E2)
    ;   note_epoch(Node, Agent, E),
        discard_superseded_arrival(Node, Agent, E),
        findall(R, written(Node, Agent, _, R, _), Rs),
        max_list([0|Rs], W),
        Answer = noted(W)               % and the last round it wrote here
    ).
serve(hold(Agent, E, K, Here, Dest, Record0, Resume), Node, Answer) :-
    (   seen(Node, Agent, E2), E2 > E
    ->  Answer = superseded(E2)
    ;   \+ hold_ok(Agent, E, K, Here, Dest, Record0, Resume)
    ->  Answer = refused(hold)
    ;   catch(check_agent_record(Record0), Refused, true),
        nonvar(Refused)
    ->  Answer = refused(Refused)
    ;   note_epoch(Node, Agent, E),
        node_property(Node, tokens(Tokens)),
        setarg(4, Record0, Tokens),         % as an arrival: this node's tokens
        lease_s(Node, L),
        get_time(Now),
        Expiry is Now + L,
        locked(( forall(( ckpt(Node, Agent, E1, K1, _, _, _, _, _),
                          ( E1 < E ; E1 =:= E, K1 =< K ) ),
                        retractall(ckpt(Node, Agent, E1, K1, _, _, _, _, _))),
                 assertz(ckpt(Node, Agent, E, K, Here, Dest, Record0, Resume, Expiry)),
                 ensure_watchdog )),
        Answer = held
    ).
serve(supersede(Agent, E, K), Node, Answer) :-
    note_epoch(Node, Agent, E),
    (   current_prolog_flag(dfrl_replace_stale, true)
    ->  with_custody(Node, replace_stale(Node, Agent, E, K, Answer))
    ;   lease_custody(Node, Agent, custody(E0, K0, _))
    ->  Answer = kept(E0, K0)
    ;   Answer = none
    ).

%   What a peer may store as a checkpoint to resurrect (it is installed
%   unchecked then, beyond the sandbox check of its code): the agent's
%   record with its custody, and a resume point that starts a new round
%   with nothing aggregated (no packed term from a peer is ever read).
hold_ok(Agent, E, K, Here, Dest, Record, resume(State, Next, round_done(R, false))) :-
    atom(Agent), integer(E), integer(K),
    ground(Here-Dest),
    Record = agent(Agent, _, mobile, [], _, _, Clauses, _),
    is_list(Clauses),
    memberchk((dfrl_custody_of(Agent, custody(E, K, _)) :- true), Clauses),
    is_dict(State),
    get_dict(acc, State, none),
    get_dict(index, State, I), integer(I),
    integer(Next), integer(R).

%   A copy of Agent held here is stale for an arriving copy of epoch E
%   that left its hop K if it has a lower epoch (a late original: a
%   resurrection superseded it; it is stopped), or Agent's epoch and an
%   earlier hop and it never started here (staged or in doubt: its
%   source kept the agent, which went on, so that source decided
%   aborted). An active copy of the same epoch is never touched.
replace_stale(Node, Agent, E, K, Answer) :-
    (   \+ agent_exists(Node, Agent)
    ->  Answer = none
    ;   lease_custody(Node, Agent, custody(E0, K0, _)),
        (   E0 < E
        ->  true
        ;   E0 =:= E, K0 < K, arrived_only(Node, Agent)
        )
    ->  (   arrived_only(Node, Agent)
        ->  agent_remove(Node, Agent),
            custody_unstage(Node, Agent)
        ;   log_replaced(Node, Agent, E0, E),
            agent_purge(Node, Agent)
        ),
        get_time(Now),
        assertz(gone(Node, Agent, E0, K0, superseded, Now)),
        prune_gone(Node, Agent),
        print_message(warning,
                      format("dfrl: stale copy of ~w (epoch ~w, hop ~w) replaced by one of epoch ~w, hop ~w",
                             [Agent, E0, K0, E, K])),
        Answer = replaced(E0, K0)
    ;   lease_custody(Node, Agent, custody(E0, K0, _)),
        Answer = kept(E0, K0)
    ).

%   A copy that ran here (parked, cut off with its old epoch E0) is
%   stopped for the arriving copy of epoch E: its round log says so, as
%   when a copy retires by itself (event superseded, how: replaced).
log_replaced(Node, Agent, E0, E) :-
    (   catch(( agent_module(Node, Agent, M),
                M:dfrl_plan(Agent, plan(_, _, _, Log, _)),
                (   catch(get_state(M, Agent, S), _, fail),
                    get_dict(round, S, Round)
                ->  true
                ;   Round = null
                ),
                with_node(Node, log_event(Log, _{event:superseded, agent:Agent, round:Round,
                                                 epoch:E0, by:E, how:replaced}))
              ), Err, ( print_message(warning, Err), fail ))
    ->  true
    ;   true                            % not a dFRL agent: nothing to log
    ).

%   A copy of Agent that arrived here from a source that died before
%   deciding (staged or in_doubt) is superseded by a resurrection with
%   the higher epoch E: it must never start, and its name must be free
%   for the resurrected agent's next visit. Discarded as migration.pl
%   discards an aborted arrival; a source that committed after all is
%   then told not_staged.
discard_superseded_arrival(Node, Agent, E) :-
    with_custody(Node,
                 (   agent_exists(Node, Agent),
                     arrived_only(Node, Agent),
                     lease_custody(Node, Agent, custody(E0, _, _)),
                     E0 < E
                 ->  agent_remove(Node, Agent),
                     custody_unstage(Node, Agent),
                     print_message(informational,
                                   format("dfrl: arrival of ~w (epoch ~w) discarded: superseded by epoch ~w",
                                          [Agent, E0, E]))
                 ;   true
                 )).

%   What a peer may write into a checkpoint (installed unchecked if it
%   is resurrected): `alive`, or the end of a round with the agent's
%   plan and method as plain ground facts of the shapes the agent sends.
progress_ok(_, alive).
progress_ok(_, started(Round)) :-
    integer(Round).
progress_ok(Agent, round_done(Round, Last, Facts)) :-
    integer(Round),
    memberchk(Last, [true, false]),
    ground(Facts),
    is_list(Facts),
    forall(member(F, Facts), progress_fact(Agent, F)).

progress_fact(Agent, dfrl_plan(Agent, plan(It, Rounds, Rest, Log, Timeout))) :-
    is_list(It),
    forall(member(S, It), ( S = stop(H, P, R), atomic(H), integer(P), atom(R) )),
    integer(Rounds), number(Rest), atomic(Log), number(Timeout).
progress_fact(Agent, dfrl_plan(Agent, plan(It, Rounds, Rest, console(H, P, File), Timeout))) :-
    progress_fact(Agent, dfrl_plan(Agent, plan(It, Rounds, Rest, File, Timeout))),
    atomic(H), integer(P).
progress_fact(Agent, dfrl_method_of(Agent, Method)) :-
    atom(Method).

%   A round ended where the agent is: a resurrection starts the next
%   round from the holder, with the facts (plan, method) as they are now.
apply_progress(alive, _, Rec, Res, Rec, Res).
apply_progress(round_done(Round, Last, Facts), _, Rec0, resume(S0, Next, _),
               Rec, resume(S0, Next, round_done(Round, Last))) :-
    Rec0 = agent(Name, H, K, T, P, Preds, Cls0, Hops),
    foldl(replace_fact, Facts, Cls0, Cls),
    Rec = agent(Name, H, K, T, P, Preds, Cls, Hops).

%   What Node knows of Agent for a holder of its checkpoint (epoch E, hop
%   K): superseded(E2), here(E1, K1) or staged(E1, K1) (the agent is on
%   Node), left(E, K2) or finished(E, K2) (a later hop passed here),
%   written(E1, Ago) (a copy of epoch E1 >= E wrote a robot of Node Ago
%   seconds ago, less than a lease: it lives, wherever its holder is), or
%   unknown.
probe_answer(Node, Agent, E, K, Answer) :-
    (   seen(Node, Agent, E2), E2 > E
    ->  Answer = superseded(E2)
    ;   agent_exists(Node, Agent)
    ->  lease_custody(Node, Agent, custody(E1, K1, _)),
        (   arrived_only(Node, Agent)
        ->  Answer = staged(E1, K1)
        ;   Answer = here(E1, K1)
        )
    ;   findall(K1-left, ( ckpt(Node, Agent, E, K1, _, _, _, _, _), K1 > K ), L1),
        findall(K1-How, ( gone(Node, Agent, E, K1, How0, _), K1 >= K,
                          gone_how(How0, How) ), L2),
        append(L1, L2, L),
        L \== []
    ->  msort(L, Sorted),
        last(Sorted, K2-How),
        Answer =.. [How, E, K2]
    ;   last_write(Node, Agent, E1, T),
        E1 >= E,
        get_time(Now),
        lease_s(Node, L),
        Ago is Now - T,
        Ago < L
    ->  Answer = written(E1, Ago)       % the agent lives: it wrote here just now
    ;   Answer = unknown
    ).

%   The agent arrived at Node and waits for its source's decision
%   (migration.pl): it has not run here, and it will not unless its
%   source committed.
arrived_only(Node, Agent) :-
    agent_status(Node, Agent, Status),
    ( Status = staged(_) ; Status = in_doubt(_, _) ),
    !.

gone_how(released(_), left).
gone_how(finished, finished).
gone_how(superseded, finished).
