:- module(dfrl_lease,
          [ lease_depart/6,             % +Node, +Agent, +Here, +Dest, +Resume, -Ticket
            lease_departed/1,           % +Ticket
            lease_stayed/1,             % +Ticket
            lease_arrived/3,            % +Node, +Agent, -Verdict
            lease_check/3,              % +Node, +Agent, -Verdict
            lease_progress/4,           % +Node, +Agent, +Progress, -Verdict
            lease_ended/3,              % +Node, +Agent, +How
            lease_checkpoint/4,         % ?Node, ?Agent, ?Epoch, ?Dest
            lease_epoch_seen/3,         % ?Node, ?Agent, ?Epoch
            lease_adopt/5,              % +Node, +Agent, +Here, +Offers, -Holder
            lease_needs_holder/2,       % +Node, +Agent
            lease_write_gate/2,         % +Node, +Agent
            lease_fenced/4,             % +Node, +Options, -Verdict, -Why
            lease_note_write/3,         % +Node, +Robot, +Options
            lease_supersede/5           % +Node, +Agent, +Address, +Tokens, -Answer
          ]).
:- use_module('../agents', [agent_export/3, agent_property/3]).
:- use_module(lease_book).
:- reexport(lease_book,                         % +Node, +Agent, -Custody;
            [lease_custody/3, lease_valid/2, copy_owned/2]). % +Node, +Agent (both)
:- use_module(lease_watch, [ensure_watchdog/0]).
:- use_module(lease_beat, [note_beat/2, beat_answer/6]).
:- use_module(lease_requests, []).             % the holder's side: its requests
:- reexport(lease_watch, [lease_broadcast_epoch/5]). % +Node, +Tokens, +Agent, +Epoch, +Stops
:- autoload(library(apply), [exclude/3]).
:- autoload(library(debug), [debug/3]).

/** <module> Checkpoints, leases and epochs of the dFRL agent (custody)

The dFRL agent (dfrl_agent.pl) must outlive the node it runs on, and the
node it rests on. This module keeps, at another stop (normally the one
the agent came from), a checkpoint of the agent and resurrects it from
there when the node the agent is on stops answering: the agent has a
holder at every instant, resting included.

## The protocol

The agent carries, as payload, custody(Epoch, Seq, Holder): its epoch
(1 at creation), the number Seq of the hop that brought it here, and the
address of the stop that holds the checkpoint covering it (`none` until
it gets one: at its first stop after a launch, right after a
resurrection).

  1. *Depart.* Before a move from stop A to stop B the agent sets its
     custody to custody(E, Seq+1, A), and A records a checkpoint: the
     agent's full record as it leaves (payload, plan, state), the state
     it had before the move (to resume from) and a lease that expires
     after the node option `lease_s` (default 10 s). If the move fails
     the checkpoint is dropped and the old custody restored.
  2. *Release.* Once the move has succeeded, A's thread tells the old
     holder (the stop before A) that it may drop its checkpoint for
     Seq: the agent is now covered by A's. An agent that finishes (or
     retires) releases its holder the same way.
  3. *Adopt.* An agent with no holder (custody `none`; or its holder
     answered that it holds no checkpoint of it, e.g. it restarted)
     asks another stop of its itinerary to hold one before it works or
     rests (lease_adopt/5, request `hold`, at its round start and before
     its rest): the stops after it first, then those before. The holder
     stores the agent's record as it is (its code passes the sandbox
     check as an arrival's does) with a resume point that starts the
     round again from the holder without this stop. The custody advances
     by one hop, so the agent's next departure releases that holder as
     any hop does.
  4. *Heartbeat.* While an agent is on a node (from lease_arrived/3 on),
     a thread of that node's process renews the holder's lease every
     third of `lease_s` (progress(alive)), whatever the agent does: it
     rests, waits for a robot, works. So a lease runs out only when the
     node the agent is on has not answered for a whole lease (killed,
     frozen, cut off).
  5. *Lease.* When a checkpoint's lease expires without a release, the
     holder probes B (`probe`, up to 2 tries (one if it timed out), each within a quarter of
     the lease: it only confirms what the missing heartbeats said):
     B answers here(E, Seq) if the agent is registered there (running or
     idle), staged(E, Seq) if it arrived there and waits for its source's
     decision (staged or in doubt), left(E, Seq') if it holds a checkpoint or
     a record of a later departure, finished(E, Seq) if the tour ended
     there, superseded(E') if it knows a higher epoch, written(E1, Ago)
     if a copy of epoch E1 >= E wrote one of its robots less than a
     lease ago, or unknown.
     `here` and `staged` renew the lease; `left`, `finished` and
     `superseded` drop the checkpoint; `unknown`, `written` and no
     answer at all make the holder ask every other stop of the itinerary
     the same question. If B did not answer and another stop answers
     `written`, the agent lives (the holder was the one cut off) and the
     holder asks again half a lease later. Only if none knows of a later hop (or a higher epoch) is
     the agent *resurrected*; a copy *staged* at another stop does not
     count (its source died between transfer and commit, so it never
     ran, and only that source could decide to start it):
     installed at the holder from the checkpoint with epoch E+1 (one
     more than any epoch seen), started with the event
     resurrected(E1, Dead) so that it skips the dead stop B and goes on
     from the holder exactly as if its move to B had failed (or, after a
     round end, starts the next round there). The new epoch is first
     sent to every reachable stop (`epoch`); a stop that holds a staged
     copy with a lower epoch discards it, so that the resurrected agent
     can enter it.
  6. *Progress.* When the agent ends a round it tells its holder
     (progress(round_done(N, [Plan and method facts]))), so that a resurrection
     starts round N+1 instead of repeating the end of round N, and with
     the plan and method as they are then.
  7. *Epochs.* Every node records the highest epoch it has seen of each
     agent (agents arriving, probes, releases, heartbeats, the epoch
     broadcast). An agent that arrives at a node (lease_arrived/3),
     rests (every 0.2 s), ends a round or a rest (lease_check/3 asks
     its holder), or is restarted from its node's store (custody.pl:
     it asks its holder before anything) and finds a higher epoch
     retires: it logs `superseded` and purges itself.
  8. *Stale copies.* A move refused because a copy of the agent is at
     the destination asks it (`supersede`, lease_supersede/5) to discard
     that copy if it is stale by generation: a lower epoch (a late
     original; stopped if it runs), or the same epoch, an earlier hop
     and never started there (its transfer was staged after its source
     gave up and decided aborted, e.g. a stop frozen or cut off past the
     mover's skip time). Any other copy is kept and the move stays
     refused.

## What is guaranteed, and what is not

  - A kill -9 (or crash, or restart without memory) of the node the
    agent runs or rests on, while its holder and at least one other
    stop live: the agent is resurrected within about lease_s after the
    node's last heartbeat (plus a probe: at once for a dead process,
    at most half a lease for a frozen one), and the federation goes on
    without the dead stop (which is tried again, and visited again if
    it came back, in every later round). A round it was resting before
    is not lost: the resurrection starts the next one.
  - A pause (SIGSTOP) or partition of the agent's node longer than the
    lease is taken for a death, but only by a holder that reaches a
    majority of the itinerary's stops (itself included; the lost stop
    counts only if it answered without the agent or refused the
    connection) and gets a majority to promise the new epoch (request
    `epoch`: a stop that knows a higher one refuses). A holder cut off
    with a minority resurrects nothing: it keeps its checkpoint and asks
    again every half lease, and drops it once a stop tells of a later
    hop (the agent found another holder meanwhile).
  - *Fencing.* The copy on a node writes a robot only under its side of
    the lease: until lease_s x (1 - 1%) after the request that last
    renewed it left (heartbeat, progress, hold), or after it arrived (its
    holder starts the checkpoint's lease again once the move succeeded,
    lease_departed/1). Its holder resurrects only after a whole lease_s
    without a renewal by its own clock, so the old copy has stopped
    writing by then as long as no clock runs more than 1% faster than
    another over a lease (a step of the wall clock, e.g. a manual
    reset, is not covered). A round starts only once its holder noted
    started(Round) (dfrl_agent's round gate); a copy that cannot renew
    its lease nor find another holder waits, parked, without writing,
    and retires when it meets the higher epoch. The robot's node refuses
    a write of an epoch lower than the highest it has seen of the agent,
    and a second write of a round (lease_fenced/4).
  - *Rounds.* Where the old copy may still run (the lost stop did not
    answer: cut off or frozen), the resurrected copy starts the next
    round the old one cannot have entered (resume_point/4 in
    lease_watch.pl): after a mid-round checkpoint, the next round; after
    started(R), R+1. So no round is written by two copies. Where the old
    copy is gone (its stop answered without it or refused the
    connection: killed, restarted), a chain's round goes on from the
    checkpoint as before.
  - The flag `dfrl_quorum` (per process, true) false lets a holder
    resurrect alone, as before (the control of the partition tests).
  - A pause or partition shorter than the lease never causes a
    resurrection.
  - Two faults at once are not covered: if the holder dies too before
    the agent has moved on (or, resting, before the agent's heartbeat
    has found that it holds nothing and the next round start adopts
    another), the agent is lost. An itinerary of one stop, or one whose
    other stops all refuse the checkpoint, leaves the agent without a
    holder (a warning says so).
  - Checkpoints are kept in memory: a holder that restarts has none
    (the agent adopts another holder at its next round start).

This module is the agent's side (steps 1-3, 6-8) and the requests a
holder serves; what the nodes know (checkpoints, epochs seen, the
agents that renew a lease) is in lease_book.pl, and the two threads of
steps 4 and 5 (heartbeat, watchdog with resurrection) in lease_watch.pl.

Flags (per process, both true by default): `dfrl_resting_holder` false
turns off heartbeats and adoption, `dfrl_replace_stale` false keeps
stale copies (step 8); the behaviour before them, for tests.
*/

		 /*******************************
		 *     AGENT SIDE (dfrl_agent)	*
		 *******************************/

%!  lease_depart(+Node, +Agent, +Here, +Dest, +Resume, -Ticket) is det.
%
%   Before moving Agent from Node (reached by others at Here, a
%   Host:Port or `none` for a node that is no stop) to Dest: advance its
%   custody and record the checkpoint. Resume is what a resurrection
%   resumes from (resume(StateBefore, Next, none), see dfrl_agent.pl;
%   lease_progress/4 replaces `none` by round_done(Round, Last)). Ticket
%   is passed to lease_departed/1 or lease_stayed/1.

lease_depart(Node, Agent, Here, Dest, Resume, Ticket) :-
    lease_custody(Node, Agent, Old),
    Old = custody(E, K, _),
    K1 is K + 1,
    agent_tokens(Node, Agent, Tokens),
    Ticket = ticket(Node, Agent, Old, E, K1, Tokens),
    (   Here == none
    ->  set_custody(Node, Agent, custody(E, K1, none))
    ;   set_custody(Node, Agent, custody(E, K1, Here)),
        agent_export(Node, Agent, Record0),
        without_state(Record0, Record),
        lease_s(Node, L),
        get_time(Now),
        Expiry is Now + L,
        locked(( assertz(ckpt(Node, Agent, E, K1, Here, Dest, Record, Resume,
                              Expiry)),
                 ensure_watchdog ))
    ).

%   The checkpoint's record keeps the agent's round state as
%   dfrl_state(Agent, in_resume): a resurrection resumes from the state in
%   Resume (resurrect/10 puts it back into the record), never from the
%   record's, and the state holds the aggregate (some 200 KB at 20,000
%   floats), so one copy of it is stored, not two.
without_state(Record0, Record) :-
    record_state(Record0, in_resume, Record).

%!  lease_stayed(+Ticket) is det.
%
%   The move failed: drop the checkpoint, restore the custody.

lease_stayed(ticket(Node, Agent, Old, E, K1, _)) :-
    locked(retractall(ckpt(Node, Agent, E, K1, _, _, _, _, _))),
    set_custody(Node, Agent, Old).

%!  lease_departed(+Ticket) is det.
%
%   The move succeeded: the checkpoint's lease starts again now (the
%   agent's new node counts its side of the lease from when the agent
%   arrived there, which was before: see note_valid/3), and the old
%   holder is released (best effort; a holder that misses it finds out
%   with its probe). Called from the thread that moved the agent, after
%   the move.

lease_departed(ticket(Node, Agent, custody(E, K, Holder), E, K1, Tokens)) :-
    lease_s(Node, L),
    get_time(Now),
    Expiry is Now + L,
    locked(( retractall(valid(Node, Agent, _)),
             set_expiry(Node, Agent, E, K1, Expiry) )),
    release(Node, Tokens, Agent, Holder, E, K, left, _).

%   (8 arguments: the lease's custody fields, Epoch, Seq, Holder, and how)
release(_, _, _, none, _, _, _, none) :- !.
release(Node, Tokens, Agent, Holder, E, K, How, Answer) :-
    custody_call(Node, Tokens, Holder, release(Agent, E, K, How), Answer0),
    (   Answer0 = error(Why)
    ->  debug(dfrl(lease), 'release of ~w at ~w: ~p', [Agent, Holder, Why]),
        Answer = none
    ;   Answer = Answer0
    ).

%!  lease_ended(+Node, +Agent, +How) is det.
%
%   Agent ends on Node (How: finished or superseded): remember it and
%   release its holder. Call before purging the agent.

lease_ended(Node, Agent, How) :-
    lease_custody(Node, Agent, custody(E, K, Holder)),
    get_time(Now),
    assertz(gone(Node, Agent, E, K, How, Now)),
    locked(retractall(valid(Node, Agent, _))),
    prune_gone(Node, Agent),
    agent_tokens(Node, Agent, Tokens),
    release(Node, Tokens, Agent, Holder, E, K, How, _).

%!  lease_arrived(+Node, +Agent, -Verdict) is det.
%
%   Agent starts on Node: Verdict is superseded(E2) if Node has seen a
%   higher epoch of it, else ok (and its epoch is noted).

lease_arrived(Node, Agent, Verdict) :-
    lease_custody(Node, Agent, custody(E, _, _)),
    (   seen(Node, Agent, E2), E2 > E
    ->  Verdict = superseded(E2)
    ;   note_epoch(Node, Agent, E),
        note_arrival(Node, Agent),
        note_beat(Node, Agent),
        Verdict = ok
    ).

%   The copy's side of the lease starts when it arrived here: its holder
%   started the checkpoint's lease again once it learnt that the move
%   succeeded (lease_departed/1), which was after that.
note_arrival(Node, Agent) :-
    (   valid(Node, Agent, _)
    ->  true
    ;   agent_property(Node, Agent, arrived(T))
    ->  note_valid(Node, Agent, T)
    ;   true
    ).

%!  lease_check(+Node, +Agent, -Verdict) is det.
%
%   As lease_arrived/3, and ask the holder too: Verdict is
%   superseded(E2) if it knows a higher epoch. An unreachable holder is
%   no verdict (ok).

lease_check(Node, Agent, Verdict) :-
    lease_progress(Node, Agent, alive, Verdict).

%!  lease_progress(+Node, +Agent, +Progress, -Verdict) is det.
%
%   Tell the holder of Agent about Progress (`alive`, or
%   round_done(Round, Last, Facts): the round ended, the last one if Last
%   is true; Facts, payload facts such
%   as dfrl_plan(Agent, Plan), replace those of the checkpoint) and
%   renew its lease. Verdict as
%   lease_check/3.

lease_progress(Node, Agent, Progress, Verdict) :-
    lease_arrived(Node, Agent, V0),
    (   V0 \== ok
    ->  Verdict = V0
    ;   lease_custody(Node, Agent, custody(E, K, Holder)),
        Holder \== none
    ->  agent_tokens(Node, Agent, Tokens),
        get_time(Sent),
        custody_call(Node, Tokens, Holder, progress(Agent, E, K, Progress),
                     Answer),
        (   Answer = superseded(E2)
        ->  note_epoch(Node, Agent, E2),
            Verdict = Answer
        ;   beat_answer(Answer, Node, Agent, E, K, Sent),
            Verdict = ok
        )
    ;   Verdict = ok
    ).

%!  lease_write_gate(+Node, +Agent) is semidet.
%
%   True if the copy of Agent on Node may write a robot now: it holds
%   its lease (lease_valid/2), or its holder renews it now. A copy that
%   cannot renew its lease writes nothing: its holder may resurrect it
%   once the lease has run out by the holder's clock, and by then this
%   copy's side of it (shorter by the clock drift, lease_drift/1) has
%   run out too.

lease_write_gate(Node, Agent) :-
    (   lease_valid(Node, Agent)
    ->  true
    ;   lease_progress(Node, Agent, alive, Verdict),
        Verdict == ok,
        lease_valid(Node, Agent)
    ).

%!  lease_fenced(+Node, +Options, -Verdict, -Why) is det.
%
%   The robot's side of fencing, for a table write with Options (those
%   of the resource hook: agent(A), epoch(E), round(R)) at a robot of
%   Node: Verdict is `ok`, or `fenced` with Why (a string) when Node has
%   seen a higher epoch of the agent (a superseded copy) or this robot
%   was already written in this round or a later one by the agent (a
%   round is written once). Writes without an agent are not fenced.

lease_fenced(Node, Options, Verdict, Why) :-
    (   memberchk(agent(A), Options),
        memberchk(epoch(E), Options),
        integer(E)
    ->  (   seen(Node, A, E2), E2 > E
        ->  Verdict = fenced,
            format(string(Why), "fenced: ~w epoch ~w is superseded by epoch ~w here",
                   [A, E, E2])
        ;   note_epoch(Node, A, E),
            memberchk(round(R), Options),
            memberchk(robot(Robot), Options),
            written(Node, A, Robot, R0, E0),
            R =< R0
        ->  Verdict = fenced,
            format(string(Why), "fenced: ~w round ~w written here already (round ~w, epoch ~w)",
                   [A, R, R0, E0])
        ;   Verdict = ok,
            Why = ""
        )
    ;   Verdict = ok,
        Why = ""
    ).

%!  lease_note_write(+Node, +Robot, +Options) is det.
%
%   The agent of Options (agent(A), epoch(E), round(R)) wrote Robot on
%   Node: later writes of that round or an earlier one are fenced.

lease_note_write(Node, Robot, Options) :-
    (   memberchk(agent(A), Options),
        memberchk(epoch(E), Options),
        memberchk(round(R), Options),
        integer(R)
    ->  get_time(Now),
        locked(( retractall(written(Node, A, Robot, _, _)),
                 assertz(written(Node, A, Robot, R, E)),
                 retractall(last_write(Node, A, _, _)),
                 assertz(last_write(Node, A, E, Now)) ))
    ;   true
    ).

%!  lease_checkpoint(?Node, ?Agent, ?Epoch, ?Dest) is nondet.
%
%   Node holds a checkpoint of Agent (epoch Epoch) that went to Dest.

lease_checkpoint(Node, Agent, Epoch, Dest) :-
    ckpt(Node, Agent, Epoch, _, _, Dest, _, _, _).

%!  lease_epoch_seen(?Node, ?Agent, ?Epoch) is nondet.
%
%   Epoch is the highest epoch of Agent that Node has seen.

lease_epoch_seen(Node, Agent, Epoch) :-
    seen(Node, Agent, Epoch).

%!  lease_needs_holder(+Node, +Agent) is semidet.
%
%   Agent, on Node, has no stop that holds a checkpoint of it: at its
%   first stop after a launch, right after a resurrection, its holder
%   answered a heartbeat that it holds none (it restarted), or its lease
%   ran out or its holder did not answer a heartbeat in time (cut off,
%   frozen or dead).

lease_needs_holder(Node, Agent) :-
    current_prolog_flag(dfrl_resting_holder, true),
    lease_custody(Node, Agent, custody(E, K, Holder)),
    (   Holder == none
    ->  true
    ;   holder_lost(Node, Agent, E, K)
    ->  true
    ;   holder_silent(Node, Agent, E, K)
    ->  true
    ;   \+ lease_valid(Node, Agent)
    ).

%!  lease_adopt(+Node, +Agent, +Here, +Offers, -Holder) is det.
%
%   Find Agent (on Node, at the stop Here) a holder before it stays
%   here: Offers is a list Address-Resume, tried in order; the first
%   stop that stores a checkpoint of the agent as it is now (request
%   `hold`) becomes its holder (Holder its address; `none` if no stop
%   did). Resume is what a resurrection there resumes from, as for
%   lease_depart/6, with the progress round_done(Round, false) already
%   set and an empty aggregate. The agent's custody advances by one hop
%   (the old holder, if any, is released), so that its next departure
%   releases the new holder as any hop does.

lease_adopt(Node, Agent, Here, Offers0, Holder) :-
    lease_custody(Node, Agent, Old),
    Old = custody(E, K, OldHolder),
    (   holder_silent(Node, Agent, E, K)            % not asked again now
    ->  exclude([A-_]>>(A == OldHolder), Offers0, Offers)
    ;   Offers = Offers0
    ),
    K1 is K + 1,
    agent_tokens(Node, Agent, Tokens),
    adopt(Offers, Node, Agent, Tokens, Here, E, K1, Holder),
    (   Holder == none
    ->  set_custody(Node, Agent, Old)
    ;   locked(( retractall(holder_lost(Node, Agent, _, _)),
                 retractall(holder_silent(Node, Agent, _, _)) )),
        (   OldHolder \== none, OldHolder \== Holder
        ->  release(Node, Tokens, Agent, OldHolder, E, K, left, _)
        ;   true
        )
    ).

%   (8 arguments: a loop over the offers, with the custody fields to hand over)
adopt([], _, _, _, _, _, _, none).
adopt([Address-Resume|Offers], Node, Agent, Tokens, Here, E, K1, Holder) :-
    set_custody(Node, Agent, custody(E, K1, Address)),
    agent_export(Node, Agent, Record0),
    setarg(4, Record0, []),                 % a record that leaves holds no token
    get_time(Sent),
    quick_call(Node, Tokens, Address, hold(Agent, E, K1, Address, Here, Record0, Resume),
               Answer),
    (   Answer == held
    ->  Holder = Address,
        locked(retractall(valid(Node, Agent, _))),
        note_valid(Node, Agent, Sent),
        debug(dfrl(lease), '~w held by ~w (~w/~w)', [Agent, Address, E, K1])
    ;   debug(dfrl(lease), 'hold of ~w at ~w: ~p', [Agent, Address, Answer]),
        (   Answer = superseded(E2) -> note_epoch(Node, Agent, E2) ; true ),
        adopt(Offers, Node, Agent, Tokens, Here, E, K1, Holder)
    ).

%!  lease_supersede(+Node, +Agent, +Address, +Tokens, -Answer) is det.
%
%   Agent (on Node) was refused at Address because a copy of it is
%   there: ask Address to discard that copy if it is stale, i.e. of a
%   lower epoch, or of Agent's epoch and an earlier hop and never
%   started there (its source decided aborted, see serve/3). Answer is
%   replaced(Epoch, Seq) (the stale copy's), kept(Epoch, Seq) (it is
%   not stale: the move stays refused), none (no copy there any more)
%   or error(E).

lease_supersede(Node, Agent, Address, Tokens, Answer) :-
    lease_custody(Node, Agent, custody(E, K, _)),
    custody_call(Node, Tokens, Address, supersede(Agent, E, K), Answer).
