:- module(lease_watch,
          [ ensure_watchdog/0,
            lease_broadcast_epoch/5,    % +Node, +Tokens, +Agent, +Epoch, +Stops
            ensure_thread/1,            % +Role
            has_work/2,                 % +Role, :Work
            refused/1                   % +Why
          ]).
:- use_module('../node', [node_property/2, local_node/1]).
:- use_module('../agents',
              [ agent_exists/2, agent_install/4, agent_execute/4, agent_status/3 ]).
:- use_module('../transport', [address_normalize/2]).
:- use_module(lease_book).
:- autoload(library(lists), [member/2, memberchk/2, min_list/2]).
:- autoload(library(apply), [exclude/3]).
:- autoload(library(debug), [debug/3]).
:- autoload(library(occurs), [sub_term/2]).

/** <module> The threads of the dFRL agent's leases: the watchdog and the heartbeat

Two threads per process, each running only while it has work (steps 4
and 5 of the protocol in dfrl_lease.pl):

  - the *watchdog*, while a node of this process holds checkpoints:
    every tick it takes the checkpoints whose lease expired, probes the
    stop the agent went to, asks the other stops of its itinerary if
    that one does not know it, and resurrects the agent with a new epoch
    when none knows of a later hop;
  - the *heartbeat*, while agents are on nodes of this process: every
    third of the lease it renews each one's holder (progress(alive));
    its work is lease_beat.pl's.

Both are stopped and joined at halt.
*/

:- dynamic
    running_/2,                 % Role (watchdog or heart), ThreadId
    exited_/2,                  % Role, ThreadId: ended, to be joined
    tried_/3.                   % Node, Agent, Epoch: a resurrection that found no majority

%!  ensure_thread(+Role) is det.
%
%   Start the thread of Role (watchdog or heart) unless it runs; one that
%   ended is joined first. Called holding the lock: a thread ends, when
%   it finds no more work, under the same lock.
ensure_thread(Role) :-
    (   running_(Role, _)
    ->  true
    ;   forall(retract(exited_(Role, Old)), catch(thread_join(Old, _), _, true)),
        thread_create(run_thread(Role), Tid, []),
        assertz(running_(Role, Tid))
    ).

run_thread(Role) :-
    thread_loop(Role, Loop),
    (   catch(Loop, E, true)
    ->  true
    ;   E = error(failed(Loop), _)      % a bug: say so, never end silently
    ),
    thread_self(Me),
    locked(( retractall(running_(Role, Me)),
             assertz(exited_(Role, Me)) )),
    (   var(E) -> true ; E == stop -> true ; print_message(warning, E) ).

thread_loop(watchdog, watch_loop).
thread_loop(heart, lease_beat:heart_loop).   % (loaded by dfrl_lease.pl)

%!  has_work(+Role, :Work) is semidet.
%
%   The loop of Role goes on while Work (a goal) finds some; when it
%   finds none, the thread is no longer Role's (the next to need it
%   starts a new one).
has_work(Role, Work) :-
    locked(( Work
           ->  true
           ;   thread_self(Me), retractall(running_(Role, Me)), fail
           )).

		 /*******************************
		 *           WATCHDOG		*
		 *******************************/

%!  ensure_watchdog is det.
%
%   One thread per process, while there are checkpoints: every tick it
%   handles the checkpoints whose lease expired. It ends when there are
%   none (the next one to start joins it) or when told to stop (at halt).
%   Called holding the lock.
ensure_watchdog :-
    ensure_thread(watchdog).

watch_loop :-
    (   has_work(watchdog, ckpt(_, _, _, _, _, _, _, _, _))
    ->  tick(T),
        thread_self(Me),
        (   thread_get_message(Me, stop, [timeout(T)])
        ->  throw(stop)
        ;   true                        % the timeout: a tick
        ),
        get_time(Now),
        findall(ckpt(N, A, E, K), ( ckpt_expiry(N, A, E, K, X), X < Now ), Due),
        locked(forall(( ( renewed(N, A, E, K, _) ; entered(N, A, E, K, _) ),
                        \+ ckpt(N, A, E, K, _, _, _, _, _) ),
                      ( retractall(renewed(N, A, E, K, _)),
                        retractall(entered(N, A, E, K, _)) ))),
        forall(member(C, Due),
               catch(expired(C), Err, print_message(warning, Err))),
        watch_loop
    ;   true
    ).

tick(T) :-
    findall(L, ( ckpt(N, _, _, _, _, _, _, _, _), lease_s(N, L) ), Ls),
    (   Ls == [] -> T = 0.1 ; min_list(Ls, Min), T is max(0.02, min(0.5, Min/5)) ).

expired(ckpt(Node, Agent, E, K)) :-
    (   ckpt(Node, Agent, E, K, Here, Dest, Record, Resume, _)
    ->  (   \+ local_node(Node)
        ->  drop(Node, Agent, E, K, node_stopped)
        ;   seen(Node, Agent, E2), E2 > E
        ->  drop(Node, Agent, E, K, superseded(E2))
        ;   agent_exists(Node, Agent)
        ->  drop(Node, Agent, E, K, back_here)
        ;   probe(Node, Record, Dest, Agent, E, K, 2, Answer),
            judge(Answer, Dest, Node, Agent, E, K, Here, Record, Resume)
        )
    ;   true
    ).

%   (9 arguments: the fields of one checkpoint (ckpt/9, lease_book.pl) as the watchdog took it)
judge(here(E1, K1), _, Node, Agent, E, K, _, _, _) :-
    E1 =< E,
    !,
    (   E1 =:= E, K1 > K
    ->  drop(Node, Agent, E, K, here_later(K1))     % a later hop holds it now
    ;   renew(Node, Agent, E, K)
    ).
judge(staged(E1, _), _, Node, Agent, E, K, _, _, _) :-
    E1 =< E,
    !,
    renew(Node, Agent, E, K).
judge(Unknown, Dest, Node, Agent, E, K, Here, Record, Resume) :-
    ( Unknown == unknown ; Unknown = written(_, _) ),    % it answered without the agent
    !,
    lost(Node, Agent, E, K, Here, Dest, Record, Resume, gone, lost).
judge(error(Why), Dest, Node, Agent, E, K, Here, Record, Resume) :-
    !,
    (   refused(Why)
    ->  Dest_ = gone                    % nothing listens there: the copy died with it
    ;   Dest_ = silent                  % cut off or frozen: the copy may still run
    ),
    lost(Node, Agent, E, K, Here, Dest, Record, Resume, Dest_, unreachable(Why)).
judge(Answer, _, Node, Agent, E, K, _, _, _) :-
    (   Answer = superseded(E2) -> note_epoch(Node, Agent, E2) ; true ),
    drop(Node, Agent, E, K, Answer).

renew(Node, Agent, E, K) :-
    lease_s(Node, L),
    get_time(Now),
    Expiry is Now + L,
    locked(set_expiry(Node, Agent, E, K, Expiry)).

drop(Node, Agent, E, K, Why) :-
    debug(dfrl(lease), 'drop checkpoint ~w/~w/~w on ~w: ~p', [Agent, E, K, Node, Why]),
    get_time(Now),
    locked(retractall(tried_(Node, Agent, _))),
    locked(( retract(ckpt(Node, Agent, E, K, _, _, _, _, _))
           ->  assertz(gone(Node, Agent, E, K, released(dropped), Now))
           ;   true
           )),
    prune_gone(Node, Agent).

%   (8 arguments: a checkpoint's fields (ckpt/9) that a probe needs, and the tries)
probe(Node, Record, Dest, Agent, E, K, Tries, Answer) :-
    record_tokens(Record, Node, Tokens),
    quick_call(Node, Tokens, Dest, probe(Agent, E, K), A0),
    (   A0 = error(Why), Tries > 1,
        \+ sub_term(timeout(_), Why)    % a stop silent for a quarter lease is silent
    ->  sleep(0.1),
        T1 is Tries - 1,
        probe(Node, Record, Dest, Agent, E, K, T1, Answer)
    ;   Answer = A0
    ).

%   The stop Dest the agent went to does not have it (Dest_ = gone: it
%   answered without it, or refused the connection) or does not answer
%   (silent). Resurrect the agent only if no other stop knows of a later
%   hop or a higher epoch, and a majority of the itinerary's stops (this
%   one included; Dest if it answered) answered: a holder cut off with a
%   minority never resurrects (the majority's side may have the agent).
%   Without a majority the checkpoint is kept and asked about again half
%   a lease later.
%   (10 arguments: the fields of one checkpoint (ckpt/9) and the verdict)
lost(Node, Agent, E, K, Here, Dest, Record, Resume, Dest_, Why) :-
    others_know(Node, Dest, Dest_, Here, Record, Agent, E, K, Known, Answered),
    record_stops(Record, Agent, Stops),
    majority(Stops, Need),
    (   Dest_ == gone -> DestCount = 1 ; DestCount = 0 ),
    Have is 1 + DestCount + Answered,
    (   Known = known(Reason)
    ->  drop(Node, Agent, E, K, Reason)
    ;   Known = lives(S, Ago)
    ->  print_message(warning,
                      format("dfrl: ~w lost at ~w (~p), but ~w was written by it ~3f s ago \c
                              (less than a lease): not resurrected; asked again later",
                             [Agent, Dest, Why, S, Ago])),
        wait_again(Node, Agent, E, K)
    ;   Have >= Need
    ->  Known = max_epoch(Max),
        resurrect(Node, Agent, E, K, Max, Here, Dest, Record, Resume, Dest_, Why)
    ;   print_message(warning,
                      format("dfrl: ~w lost at ~w (~p), but only ~w of ~w stops answered \c
                              (a majority is ~w): not resurrected here; asked again later",
                             [Agent, Dest, Why, Have, Stops, Need])),
        wait_again(Node, Agent, E, K)
    ).

wait_again(Node, Agent, E, K) :-
    lease_s(Node, L),
    get_time(Now),
    Expiry is Now + L/2,
    locked(set_expiry(Node, Agent, E, K, Expiry)).

%   Does any other stop know of a later hop or a higher epoch? Answered
%   counts the stops that answered at all. An epoch this holder itself
%   tried to resurrect with (tried_/3) is no news. Where the lost stop may
%   still run the agent (Dest_ silent), a stop it wrote less than a lease
%   ago (written(E1, Ago)) shows that it lives (Known = lives(Stop, Ago)):
%   its holder was cut off, not the agent (it may not have found another
%   holder yet); asked again later. Where the lost stop is gone, its copy
%   writes nothing more and such writes are no news.
%   (10 arguments: a checkpoint's fields (ckpt/9) and what the stops answered)
others_know(Node, Dest, Dest_, Here, Record, Agent, E, K, Known, Answered) :-
    record_stops(Record, Agent, Stops0),
    exclude([S]>>( same_address(S, Dest) ; same_address(S, Here) ), Stops0, Stops),
    record_tokens(Record, Node, Tokens),
    (   tried_(Node, Agent, Tried) -> true ; Tried = E ),
    others_know_(Stops, Node, Tokens, Agent, E, K, Tried-Dest_, E, Known, 0, Answered).

%   (11 arguments: others_know/10's loop, with its accumulators)
others_know_([], _, _, _, _, _, _, Max, max_epoch(Max), N, N).
others_know_([S|Ss], Node, Tokens, Agent, E, K, Tried-Dest_, Max0, Known, N0, N) :-
    quick_call(Node, Tokens, S, probe(Agent, E, K), Answer),
    (   Answer = error(_)
    ->  N1 = N0
    ;   N1 is N0 + 1
    ),
    (   Answer = superseded(E2), E2 > Tried
    ->  Known = known(superseded(S, E2)), N = N1
    ;   Answer = here(E1, _), E1 >= E
    ->  Known = known(here(S)), N = N1  % staged(_, _): arrived, never ran: not known
    ;   ( Answer = left(_, K1) ; Answer = finished(_, K1) ), K1 > K
    ->  Known = known(Answer), N = N1
    ;   Answer = written(_, Ago), Dest_ == silent
    ->  Known = lives(S, Ago), N = N1
    ;   (   Answer = superseded(E3) -> Max1 is max(Max0, E3) ; Max1 = Max0 ),
        others_know_(Ss, Node, Tokens, Agent, E, K, Tried-Dest_, Max1, Known, N1, N)
    ).

%!  refused(+Why) is semidet.
%
%   A connection refused: the node's process is gone (killed, crashed,
%   stopped), nothing of it runs; a timeout or an unreachable network is
%   no such proof.
refused(E) :-
    sub_term(T, E),
    atom(T),
    (   T == econnrefused
    ->  true
    ;   sub_atom_icasechk(T, _, 'refused')
    ),
    !.

%   The tokens to prove for the agent: those in its checkpoint, or the
%   node's (a record may carry none).
record_tokens(Record, Node, Tokens) :-
    arg(4, Record, Tokens0),
    (   Tokens0 \== []
    ->  Tokens = Tokens0
    ;   agent_tokens(Node, none, Tokens)
    ).

record_stops(agent(_, _, _, _, _, _, Clauses, _), Agent, Stops) :-
    (   member((dfrl_plan(Agent, plan(It, _, _, _, _)) :- _), Clauses)
    ->  findall(H:P, member(stop(H, P, _), It), Stops0),
        sort(Stops0, Stops)
    ;   Stops = []
    ).

same_address(A, B) :-
    catch(( address_normalize(A, H1:P1),
            address_normalize(B, H2:P2) ), _, fail),
    P1 =:= P2,
    (   H1 == H2
    ->  true
    ;   loopback(H1), loopback(H2)
    ).

loopback(localhost).
loopback('127.0.0.1').

%   Install the agent at the holder with a new epoch and start it with
%   resurrected(OldEpoch, Dead). The new epoch is first promised by a
%   majority of the stops (request `epoch`: each notes it and refuses
%   the old copy from then on; a stop that knows a higher one refuses
%   it), else nothing is installed and the checkpoint waits. Where the
%   old copy may still run (Dest silent), the resurrected one starts a
%   new round (its round number is one the old copy cannot have
%   entered: see resume_point/6): a round is never written by two copies.
%   (11 arguments: the fields of one checkpoint (ckpt/9), the epoch seen and the verdict)
resurrect(Node, Agent, E, K, MaxSeen, Here, Dest, Record0, Resume0, Dest_, Why) :-
    (   seen(Node, Agent, Seen) -> true ; Seen = E ),
    (   tried_(Node, Agent, Tried) -> true ; Tried = E ),
    E1 is max(max(max(E, MaxSeen), Seen), Tried) + 1,
    record_stops(Record0, Agent, Stops0),
    exclude([S]>>( same_address(S, Dest) ; same_address(S, Here) ), Stops0, Others),
    record_tokens(Record0, Node, Tokens0),
    promise(Others, Node, Tokens0, Agent, E1, 0-0, Promised-Written, Refused),
    majority(Stops0, Need),
    (   Dest_ == gone -> DestCount = 1 ; DestCount = 0 ),
    (   Refused == none,
        1 + DestCount + Promised >= Need
    ->  locked(( retract(ckpt(Node, Agent, E, K, _, _, _, _, _)),
                 retractall(tried_(Node, Agent, _)) )),
        resurrect_(Node, Agent, E1, K, Here, Dest, Record0, Resume0, Dest_, Written, Why)
    ;   Refused = superseded(E2)
    ->  note_epoch(Node, Agent, E2),
        drop(Node, Agent, E, K, superseded(E2))
    ;   locked(( retractall(tried_(Node, Agent, _)),
                 assertz(tried_(Node, Agent, E1)) )),
        print_message(warning,
                      format("dfrl: ~w: epoch ~w promised by ~w stops, a majority is ~w: \c
                              not resurrected; asked again later", [Agent, E1, Promised, Need])),
        wait_again(Node, Agent, E, K)
    ).

%   promise(+Stops, +Node, +Tokens, +Agent, +Epoch, +Acc0, -Acc, -Refused)
%
%   Acc is Promised-Written: how many of Stops promised Epoch, and the
%   last round the agent wrote at any of them (a stop answers noted(W);
%   one of before issue 33 answers noted: 0).
%   (8 arguments: a loop over the stops with a pair of accumulators)
promise([], _, _, _, _, Acc, Acc, none).
promise([S|Ss], Node, Tokens, Agent, E1, N0-W0, Acc, Refused) :-
    quick_call(Node, Tokens, S, epoch(Agent, E1), Answer),
    (   ( Answer == noted -> W = 0 ; Answer = noted(W), integer(W) )
    ->  N1 is N0 + 1,
        W1 is max(W0, W),
        promise(Ss, Node, Tokens, Agent, E1, N1-W1, Acc, Refused)
    ;   Answer = superseded(E2), E2 > E1
    ->  Acc = N0-W0, Refused = superseded(E2)
    ;   promise(Ss, Node, Tokens, Agent, E1, N0-W0, Acc, Refused)
    ).

%   resume_point(+Dest_, +Itinerary, +Entered, +Written, +Resume0, -Resume)
%
%   Where a resurrection resumes. A copy enters a round only once its
%   holder noted it (progress started(Round), kept as entered/5: Entered
%   is that round, or none); Written is the last round the agent wrote
%   at any stop that promised the new epoch. Where the old copy is gone
%   (its stop answered without it or refused the connection), a chain
%   goes on as before: a mid-round checkpoint goes on with its round; a
%   round it had entered at its first stop, before its first move,
%   starts again (it wrote no other robot in it: a move takes a new
%   checkpoint). Otherwise (Dest silent: cut off or frozen, the old copy
%   may still run; or a tree, whose root stays at its stop all round
%   while its copies write the other robots) the new copy starts a round
%   no copy wrote at a stop it can reach: the round the old one entered
%   (or the next one after a round_done) unless some stop has it
%   written, else the round after. A copy alone with its own robot writes
%   nothing (dfrl_agent), so a stop cut off keeps no write of that round
%   either. After a mid-round checkpoint of a silent stop: the round
%   after the state's (fresh).
resume_point(_, _, _, _, resume(S, Next, round_done(R, true)), resume(S, Next, round_done(R, true))) :- !.
resume_point(gone, chain, _, _, Resume, Resume) :- !.
resume_point(_, _, Entered, W, resume(S, Next, round_done(R0, false)), resume(S, Next, round_done(R1, false))) :-
    !,
    (   integer(Entered) -> Start0 = Entered ; Start0 is R0 + 1 ),
    Start is max(Start0, W + 1),
    R1 is Start - 1.
resume_point(_, _, _, W, resume(S, Next, none), resume(S, Next, fresh(W))).

record_itinerary(agent(_, _, _, _, _, _, Clauses, _), Agent, Kind) :-
    (   memberchk((dfrl_itinerary_of(Agent, tree(_)) :- _), Clauses)
    ->  Kind = tree
    ;   Kind = chain
    ).

%   (11 arguments: resurrect/11 once the epoch is promised)
resurrect_(Node, Agent, E1, K, Here, Dest, Record0, Resume0, Dest_, Written, Why) :-
    record_itinerary(Record0, Agent, Itinerary),
    (   entered(Node, Agent, E0, K, Entered), E0 < E1 -> true ; Entered = none ),
    resume_point(Dest_, Itinerary, Entered, Written, Resume0, Resume),
    Resume = resume(State, _, _),
    record_state(Record0, State, Record1),
    Record1 = agent(Name, H, Kind, T, P, Preds, Cls0, Hops),
    replace_fact(dfrl_custody_of(Name, custody(E1, K, none)), Cls0, Cls1),
    Record = agent(Name, H, Kind, T, P, Preds, Cls1, Hops),
    note_epoch(Node, Agent, E1),
    agent_install(Node, Record, idle, Agent),
    print_message(warning, format("dfrl: ~w lost at ~w (~p); resurrected at ~w with epoch ~w",
                                  [Agent, Dest, Why, Node, E1])),
    % The other stops heard of the new epoch (promise/8) before the agent
    % can move to one of them (a copy staged there by the dead stop is
    % discarded); Dest hears of it too, if it answers.
    record_tokens(Record, Node, Tokens),
    (   Dest_ == gone
    ->  lease_broadcast_epoch(Node, Tokens, Agent, E1, [Dest])
    ;   true
    ),
    node_property(Node, link(Link)),
    agent_execute(Node, Agent, Link, resurrected(E1, Here, Dest, Resume)).

%!  lease_broadcast_epoch(+Node, +Tokens, +Agent, +Epoch, +Stops) is det.
%
%   Tell each of Stops (Host:Port addresses) that Agent now has Epoch,
%   proving Tokens (the agent's). Unreachable stops are skipped.

lease_broadcast_epoch(Node, Tokens, Agent, Epoch, Stops) :-
    forall(member(S, Stops),
           custody_call(Node, Tokens, S, epoch(Agent, Epoch), _)).

stop_threads :-
    forall(running_(_, T), catch(thread_send_message(T, stop), _, true)),
    forall(running_(_, T), catch(thread_join(T, _), _, true)),
    forall(retract(exited_(_, T)), catch(thread_join(T, _), _, true)).

:- at_halt(stop_threads).
