:- module(lease_book,
          [ ckpt/9,                     % Node, Agent, Epoch, Seq, Here, Dest, Record, Resume, Expiry
            gone/6,                     % Node, Agent, Epoch, Seq, How, Time
            seen/3,                     % Node, Agent, Epoch
            beat/3,                     % Node, Agent, LastBeat
            holder_lost/4,              % Node, Agent, Epoch, Seq
            holder_silent/4,            % Node, Agent, Epoch, Seq
            valid/3,                    % Node, Agent, Until
            renewed/5,                  % Node, Agent, Epoch, Seq, Expiry
            entered/5,                  % Node, Agent, Epoch, Seq, Round
            set_expiry/5,               % +Node, +Agent, +Epoch, +Seq, +Expiry
            ckpt_expiry/5,              % ?Node, ?Agent, ?Epoch, ?Seq, -Expiry
            written/5,                  % Node, Agent, Robot, Round, Epoch
            last_write/4,               % Node, Agent, Epoch, Time
            lease_forget/1,             % +Node
            note_valid/3,               % +Node, +Agent, +Since
            lease_valid/2,              % +Node, +Agent
            lease_drift/1,              % -Fraction
            majority/2,                 % +Stops, -Count
            locked/1,                   % :Goal
            lease_s/2,                  % +Node, -Seconds
            lease_custody/3,            % +Node, +Agent, -Custody
            set_custody/3,              % +Node, +Agent, +Custody
            copy_owned/2,               % +Node, +Agent
            note_epoch/3,               % +Node, +Agent, +Epoch
            prune_gone/2,               % +Node, +Agent
            agent_tokens/3,             % +Node, +Agent, -Tokens
            custody_call/5,             % +Node, +Tokens, +Address, +Request, -Answer
            quick_call/5,               % +Node, +Tokens, +Address, +Request, -Answer
            record_state/3,             % +Record0, +State, -Record
            replace_fact/3              % +Fact, +Clauses0, -Clauses
          ]).
:- use_module('../node', [node_option/3, node_property/2]).
:- use_module('../agents', [agent_property/3, agent_status/3]).
:- use_module('../agent_bounds', [bounds_stop_ball/1]).
:- use_module('../transport', [transport_request/4]).
:- autoload(library(lists), [append/3, last/2]).
:- autoload(library(apply), [exclude/3]).

/** <module> What a node knows of the dFRL agent's leases, and how it asks its peers

The state of the lease protocol (dfrl_lease.pl has the protocol) on the
nodes of this process, shared by the agent's side and the holder's
(dfrl_lease.pl) and by the threads that watch leases and renew them
(lease_watch.pl):

  - ckpt/9: the checkpoints a node holds, each with its lease's expiry
    when it was stored; renewed/5: a later expiry of one (a renewal
    stores only that, not again the checkpoint, which holds the agent's
    aggregate: some 200 KB at 20,000 floats); entered/5: the round the
    agent told the holder of a checkpoint it starts (progress
    started(Round));
  - gone/6: the last 64 departures and ends of each agent a node saw;
  - seen/3: the highest epoch of each agent a node has seen;
  - beat/3: the agents on a node that renew their holder's lease;
  - holder_lost/4: an agent whose holder answered that it holds none;
  - holder_silent/4: an agent whose holder did not answer a heartbeat in
    time (the agent finds another at its next round start);
  - written/5: the last round (and epoch) in which each agent wrote each
    robot of a node (the robot's side of fencing, dfrl_lease:lease_fenced/4);
  - last_write/4: when each agent last wrote a robot of a node, and with
    which epoch (a stop written less than a lease ago tells a holder
    that the agent lives: dfrl_lease:probe_answer/5);
  - valid/3: until when the copy of an agent on a node may write (its
    side of the lease, see note_valid/3).

Every change to them is made under one mutex (locked/1). An agent's own
custody, custody(Epoch, Seq, Holder), lives in its payload
(lease_custody/3, set_custody/3). The requests to peers carry the
agent's tokens and wait at most a half (custody_call/5) or a quarter
(quick_call/5) of the lease, so that a dead peer is found out within it.
*/

:- dynamic
    ckpt/9,
    gone/6,
    seen/3,
    beat/3,
    holder_lost/4,
    holder_silent/4,
    valid/3,
    renewed/5,
    entered/5,
    written/5,
    last_write/4.

:- multifile
    node:node_stopping/1.

:- meta_predicate locked(0).

%   Flags (per process), both true by default; false gives the behaviour
%   of before, for tests that show what these parts change:
%   dfrl_resting_holder: heartbeats and lease_adopt/5 (false: an agent
%   with no holder stays without one; leases run out only by time);
%   dfrl_replace_stale: a supersede request replaces a stale copy
%   (false: the copy is kept and the arrival stays refused).
:- create_prolog_flag(dfrl_resting_holder, true, [type(boolean), keep(true)]).
:- create_prolog_flag(dfrl_replace_stale, true, [type(boolean), keep(true)]).
%   dfrl_quorum: a holder resurrects only with a majority of the stops
%   answering and promising the new epoch (false: it resurrects alone, as
%   before issue 33; the control of the partition tests).
:- create_prolog_flag(dfrl_quorum, true, [type(boolean), keep(true)]).

%!  locked(:Goal) is semidet.
%
%   Run Goal holding the lease book's mutex.

locked(Goal) :-
    with_mutex(dfrl_lease, Goal).

%!  lease_s(+Node, -Seconds) is det.
%
%   The lease of Node's checkpoints: node option `lease_s` (default 10).

lease_s(Node, L) :-
    (   catch(node_option(Node, lease_s, L0), _, fail),
        number(L0), L0 > 0
    ->  L = L0
    ;   L = 10
    ).

%!  lease_custody(+Node, +Agent, -Custody) is det.
%
%   Custody is custody(Epoch, Seq, Holder) of Agent on Node (read from
%   its payload; custody(1, 0, none) for an agent without one).

lease_custody(Node, Agent, Custody) :-
    (   agent_property(Node, Agent, module(M)),
        catch(M:dfrl_custody_of(Agent, C), _, fail)
    ->  Custody = C
    ;   Custody = custody(1, 0, none)
    ).

%!  set_custody(+Node, +Agent, +Custody) is det.

set_custody(Node, Agent, Custody) :-
    copy_owned(Node, Agent),
    agent_property(Node, Agent, module(M)),
    retractall(M:dfrl_custody_of(Agent, _)),
    assertz(M:dfrl_custody_of(Agent, Custody)).

%!  copy_owned(+Node, +Agent) is det.
%
%   The calling thread may change Agent's state on Node: it is not a
%   thread of an earlier copy of the agent, replaced (purged, then a new
%   copy installed under the same name) while it waited on a peer. Such
%   a thread stops as a purged call ('$dfrl_purged', ended quietly by
%   the handler); it must never write into the new copy's module.

copy_owned(Node, Agent) :-
    (   agent_status(Node, Agent, running(T)),
        thread_self(Me),
        T \== Me
    ->  throw('$dfrl_purged')
    ;   true
    ).

%!  note_epoch(+Node, +Agent, +Epoch) is det.
%
%   Node has seen Epoch of Agent (the highest is kept).

note_epoch(Node, Agent, E) :-
    locked(( seen(Node, Agent, E0), E0 >= E
           ->  true
           ;   retractall(seen(Node, Agent, _)),
               assertz(seen(Node, Agent, E))
           )).

%!  set_expiry(+Node, +Agent, +Epoch, +Seq, +Expiry) is det.
%
%   The lease of the checkpoint Epoch/Seq of Agent on Node now runs to
%   Expiry (if Node holds it). Call holding the lock.

set_expiry(Node, Agent, E, K, Expiry) :-
    retractall(renewed(Node, Agent, E, K, _)),
    (   ckpt(Node, Agent, E, K, _, _, _, _, _)
    ->  assertz(renewed(Node, Agent, E, K, Expiry))
    ;   true
    ).

%!  ckpt_expiry(?Node, ?Agent, ?Epoch, ?Seq, -Expiry) is nondet.
%
%   Expiry is when the lease of a checkpoint runs out: the later of its
%   stored expiry and its last renewal.

ckpt_expiry(Node, Agent, E, K, Expiry) :-
    ckpt(Node, Agent, E, K, _, _, _, _, X0),
    (   renewed(Node, Agent, E, K, X1)
    ->  Expiry is max(X0, X1)
    ;   Expiry = X0
    ).

%!  lease_drift(-Fraction) is det.
%
%   The bound on how much faster one host's clock may run than
%   another's over a lease (rate, not offset): 1%. A copy's side of the
%   lease ends that much sooner than its holder's.

lease_drift(0.01).

%!  note_valid(+Node, +Agent, +Since) is det.
%
%   The holder of Agent granted or renewed its lease in answer to a
%   request that left Node at time Since (Node's clock), or the agent
%   arrived on Node at Since by a move its holder recorded after it: the
%   holder's lease runs to at least Since + lease_s by the holder's
%   clock, so the copy on Node may write until Since + lease_s x (1 -
%   drift) by its own (valid/3). A later grant only extends it.

note_valid(Node, Agent, Since) :-
    lease_s(Node, L),
    lease_drift(D),
    Until is Since + L * (1 - D),
    locked(( valid(Node, Agent, U0), U0 >= Until
           ->  true
           ;   retractall(valid(Node, Agent, _)),
               assertz(valid(Node, Agent, Until))
           )).

%!  lease_valid(+Node, +Agent) is semidet.
%
%   The copy of Agent on Node holds its lease now: it has no holder
%   (nobody can resurrect it: after a launch or a resurrection, before
%   it adopts one), its holder holds no checkpoint of it (holder_lost/4:
%   it answered so, or its process is gone), or its side of the lease
%   (valid/3) has not run out.

lease_valid(Node, Agent) :-
    lease_custody(Node, Agent, custody(E, K, Holder)),
    (   Holder == none
    ->  true
    ;   holder_lost(Node, Agent, E, K)
    ->  true
    ;   valid(Node, Agent, Until),
        get_time(Now),
        Now < Until
    ).

%!  majority(+Stops, -Count) is det.
%
%   Count is the majority of the distinct stops Stops: more than half
%   (1 when the flag dfrl_quorum is false).

majority(Stops, Count) :-
    (   current_prolog_flag(dfrl_quorum, false)
    ->  Count = 1
    ;   sort(Stops, Set),
        length(Set, N),
        Count is N // 2 + 1
    ).

%!  prune_gone(+Node, +Agent) is det.
%
%   Keep the last 64 records of departures and ends per agent and node.

prune_gone(Node, Agent) :-
    findall(T, gone(Node, Agent, _, _, _, T), Ts),
    length(Ts, N),
    (   N > 64
    ->  msort(Ts, Sorted),
        Drop is N - 64,
        length(Old, Drop),
        append(Old, _, Sorted),
        last(Old, Cut),
        locked(forall(( gone(Node, Agent, E, K, H, T), T =< Cut ),
                      retract(gone(Node, Agent, E, K, H, T))))
    ;   true
    ).

%!  agent_tokens(+Node, +Agent, -Tokens) is det.
%
%   The tokens Agent proves to peers: its own, else Node's.

agent_tokens(Node, Agent, Tokens) :-
    (   agent_property(Node, Agent, tokens(Tokens))
    ->  true
    ;   node_property(Node, tokens(Tokens))
    ->  true
    ;   Tokens = []
    ).

%!  custody_call(+Node, +Tokens, +Address, +Request, -Answer) is det.
%
%   One authenticated request, with timeouts bounded by half the lease;
%   Answer is error(E) if it could not be made. An exception that stops
%   the agent's call (it was purged meanwhile: bounds_stop_ball/1) is
%   thrown on: a copy replaced while it waited must not go on.

custody_call(Node, Tokens, Address, Request, Answer) :-
    lease_s(Node, L),
    node_option(Node, connect_timeout, CT0),
    node_option(Node, reply_timeout, RT0),
    CT is max(0.25, min(CT0, L/2)),
    RT is max(0.25, min(RT0, L/2)),
    request(Address, Tokens, Request, CT, RT, Answer).

%!  quick_call(+Node, +Tokens, +Address, +Request, -Answer) is det.
%
%   As custody_call/5 within a quarter of the lease: probes and
%   heartbeats only confirm what missing heartbeats said.

quick_call(Node, Tokens, Address, Request, Answer) :-
    lease_s(Node, L),
    node_option(Node, connect_timeout, CT0),
    node_option(Node, reply_timeout, RT0),
    T is max(0.25, min(min(CT0, RT0), L/4)),
    request(Address, Tokens, Request, T, T, Answer).

request(Address, Tokens, Request, CT, RT, Answer) :-
    catch(transport_request(Address, dfrl_custody(Request), Answer,
                            [ connect_timeout(CT), reply_timeout(RT),
                              tokens(Tokens), action(custody) ]),
          E, ( bounds_stop_ball(E) -> throw(E) ; Answer = error(E) )).

%!  record_state(+Record0, +State, -Record) is det.
%
%   Record0 with the agent's round state dfrl_state(Agent, State).

record_state(Record0, State, Record) :-
    Record0 = agent(Name, H, K, T, P, Preds, Cls0, Hops),
    replace_fact(dfrl_state(Name, State), Cls0, Cls),
    Record = agent(Name, H, K, T, P, Preds, Cls, Hops).

%!  replace_fact(+Fact, +Clauses0, -Clauses) is det.
%
%   Clauses0 with the facts of Fact's predicate and first argument
%   replaced by Fact.

replace_fact(Fact, Cls0, Cls) :-
    functor(Fact, F, A),
    functor(Old, F, A),
    arg(1, Fact, Name),
    arg(1, Old, Name),
    exclude([C]>>( C = (Old0 :- _), subsumes_term(Old, Old0) ), Cls0, Cls1),
    Cls = [(Fact :- true)|Cls1].

%!  lease_forget(+Node) is det.
%
%   Node forgets all it knows of agents' leases, epochs and writes, as
%   when it stops: a robot host that starts serving another experiment
%   (whose agent may bear the same name) calls it.

%   A node that stops forgets its checkpoints, as a process that dies.
node:node_stopping(Node) :-
    lease_forget(Node).

lease_forget(Node) :-
    locked(( retractall(ckpt(Node, _, _, _, _, _, _, _, _)),
             retractall(gone(Node, _, _, _, _, _)),
             retractall(seen(Node, _, _)),
             retractall(beat(Node, _, _)),
             retractall(holder_lost(Node, _, _, _)),
             retractall(holder_silent(Node, _, _, _)),
             retractall(valid(Node, _, _)),
             retractall(renewed(Node, _, _, _, _)),
             retractall(entered(Node, _, _, _, _)),
             retractall(written(Node, _, _, _, _)),
             retractall(last_write(Node, _, _, _)) )).
