:- module(migration,
          [ agent_move/3,               % +Name, +Address, +Options
            agent_clone/4,              % +Name, +Address, -Clone, +Options
            agent_resolve/2,            % +Name, +Decision
            migration_decision/3,       % ?Node, ?MigrationId, ?Decision
            migration_start/1,          % +Node
            migration_settle/1          % +Node
          ]).
:- reexport(custody, [custody_agents/2]).
:- use_module(node,
              [ current_node/1, node_property/2, node_option/3,
                node_for_address/2, ctx_node/2, ctx_authenticated/1 ]).
:- use_module(agents).
:- use_module(custody).
:- use_module(agent_bounds, [bounds_admit/3, bounds_arrived/4, bounds_install/5,
                              bounds_peer/3]).
:- autoload(library(aggregate), [aggregate_all/3]).
:- use_module(transport).
:- use_module(hop_probe, [hop_probe/1]).      % compiled away unless benchmarking
:- use_module(platform_errors, [transport_error/2]).
:- use_module(code_safety,
              [ check_agent_record/1, code_trusted/1, record_seal/3,
                record_sealed/3 ]).
:- autoload(library(error),
            [must_be/2, existence_error/2, permission_error/3]).
:- autoload(library(option), [option/2, option/3]).
:- autoload(library(debug), [debug/3]).
:- autoload(library(lists), [min_list/2, member/2, append/3]).

/** <module> Migration and cloning of agents between nodes, with custody

Moving agent A from source S to destination D is a hand-over in which
exactly one side owns A at every instant and the owner is decided once,
by S, and recorded durably (with the node option `store(Dir)`; see
custody.pl for the files and recovery):

  | step | S (source)                              | D (destination)                      |
  |------|-----------------------------------------|--------------------------------------|
  | 1    | A becomes departing(M), M is *pending*  |                                      |
  | 2    | sends transfer(M, Mode, S, T, Record, I)|                                      |
  | 3    |                                         | installs A staged(M), stores it, answers ok(staged(A)) |
  | 4    | on that answer: stores committed(M)     |                                      |
  | 5    | sends commit(M) (a request), removes its copy | stores A active, starts it, answers ok(started(A)) |
  | 6    | on that answer: forgets committed(M)    |                                      |

S removes its copy of a moved A right after the commit frame is written,
not before: the destination starts A meanwhile (the removal was some
0.06 ms of a hop, measured with `dfrl bench migrate --timeline`). The
copy is departing(M) and committed, so nothing runs it: an exception
that reaches agent_move/3 after the decision removes it instead of
restoring it. An arrival of A at S that finds it there (A came straight
back before S's thread got to it) removes it first, and whichever of the
two comes second finds nothing to remove (remove_departed/3, under the
custody mutex: the removal deletes A's custody file, which a new staged
copy of A would have replaced).

I is S's incarnation (custody_incarnation/2). Without the staged answer
(refusal, reply timeout, closed connection, a failure to store the
decision) S decides aborted, keeps A running and agent_move/3 raises the
reason. An `aborted` is never stored: S answers aborted for every M it
has no record of (*presumed abort*), and it never commits an M it does
not remember, so a restarted S (which forgot every pending M) is right
to answer so.

A staged A never starts without learning committed(M), and S never runs
A again after committed(M): at no instant do two live copies exist,
whatever the timeouts (they only decide how soon a fault is noticed).
A is never lost: S removes its copy only after D stored A as staged and
S stored committed(M); D discards A only when S answers aborted.

*Settling.* Each node runs a settle thread (started by the hook
node:node_started/1 or on first use; period: node option
`settle_period`, default 2 s). As destination it asks the source of
every agent staged longer than `commit_timeout` (and every in_doubt
one) migration_status(M):

  - committed: start A;  aborted: discard the staged copy;
  - pending: S is still deciding; ask again later;
  - unknown(I'): no record at S. If I' is the incarnation S sent in the
    transfer, S never committed (presumed abort): discard. If it differs,
    S restarted without its store and lost whatever it held: start A
    (D's copy is the only one left). A transfer without an incarnation
    (transfer/5, older peers) keeps A in_doubt;
  - no answer: A is in_doubt(M, S); ask again next period.

As source it sends commit(M) again for every committed decision not yet
confirmed (D answers started(A) or not_staged), then forgets it. A node
restarted with its store recovers its agents and decisions first, so a
kill -9 of either side at any moment, lost or delayed frames, SIGSTOP
past every timeout and cut links all settle to exactly one running copy
without an operator. agent_resolve/2 remains for agents of old peers
and for a staged agent whose source never answers again (only the
source knows whether it committed).
*/

:- dynamic
    pending_/2,                 % Node, MigId
    arrival_/3,                 % Node, MigId, Departed
    settler_/3.                 % Node, Thread, Queue

:- multifile
    node:platform_request/4,
    node:node_started/1,
    node:node_stopping/1.

node:node_started(Node) :-
    migration_start(Node).

node:node_stopping(Node) :-
    migration_stop(Node).

%!  agent_move(+Name, +Address, +Options) is det.
%
%   Move agent Name from the current node to the platform at Address
%   (weak migration: its code and payload travel; at the destination its
%   handler starts again with Event `main`). Succeeds once the
%   destination holds the agent and this node decided (durably, with a
%   store) that it has left; otherwise the agent stays here (decided
%   aborted) and the error says why. May be called from the agent's own
%   handler (the usual Tartarus style) or for an idle agent. Options:
%   connect_timeout(S), reply_timeout(S) (default: the node's).
%
%   @error existence_error(agent, Name)
%   @error permission_error(move, static_agent, Name)
%   @error permission_error(enter, platform, Address) if the destination
%   refused the tokens (this node's and the agent's) proved for it.
%   @error permission_error(install, code, Culprit) if the destination's
%   sandbox refused the agent's code (code_safety.pl); the agent stays.
%   @error transport_error(Address, Reason)

agent_move(Name, Address0, Options) :-
    hop_probe(move_called),
    must_be(atom, Name),
    address_normalize(Address0, Address),
    current_node(Node),
    migration_start(Node),
    local_node_at(Address, Local),
    (   Local == Node
    ->  move_here(Node, Name)
    ;   with_agents_locked(begin_departure(Node, Name, MigId, Previous)),
        catch(transfer(Node, Name, Address, move, MigId, _Final, Options, Local),
              E,
              ( with_agents_locked(restore(Node, Name, MigId, Previous, Left)),
                (   Left == true
                ->  remove_departed(Node, Name, MigId)
                ;   true
                ),
                throw(E)
              ))
    ).

%   The node of this process at Address (by node identity: see
%   node_for_address/2), or `none`. Asked once per move: whether the
%   agent stays, and whether its record is sealed for a node of this
%   process.
local_node_at(Address, Local) :-
    (   node_for_address(Address, Local0)
    ->  Local = Local0
    ;   Local = none
    ).

%   The move raised E: the agent runs here again as before (Left =
%   false), unless its move was committed (an exception, a signal, came
%   after the decision, before its copy was removed): it has left then,
%   and never runs here again (Left = true: the copy is to be removed,
%   outside the registry mutex, which is taken after the custody one).
restore(Node, Name, MigId, Previous, Left) :-
    (   departing_copy(Node, Name, MigId)
    ->  (   custody_decision(Node, MigId, committed)
        ->  Left = true
        ;   agent_set_status(Node, Name, Previous),
            Left = false
        )
    ;   Left = false
    ).

begin_departure(Node, Name, MigId, Previous) :-
    agent_status(Node, Name, Previous),
    (   agent_property(Node, Name, kind(static))
    ->  permission_error(move, static_agent, Name)
    ;   Previous == idle
    ->  true
    ;   Previous = running(Tid), thread_self(Tid)
    ->  true
    ;   permission_error(move, agent, Name)
    ),
    new_migration_id(Node, Name, MigId),
    assertz(pending_(Node, MigId)),
    agent_set_status(Node, Name, departing(MigId)).

%   Moving to the node it is on: start the handler again with main.
move_here(Node, Name) :-
    node_property(Node, link(Link)),
    agent_execute(Node, Name, Link, main).

new_migration_id(Node, Name, Id) :-
    random_between(0, 0xffffffffffff, R),
    get_time(T),
    format(atom(Id), '~w/~w/~16r/~0f', [Node, Name, R, T*1000000]).

%!  agent_clone(+Name, +Address, -Clone, +Options) is det.
%
%   Send a copy of agent Name to the platform at Address under a fresh
%   name Clone; the copy starts there with Event `main`, the original
%   stays. The atom Name is replaced by Clone in the copy's clauses.

agent_clone(Name, Address0, Clone, Options) :-
    must_be(atom, Name),
    address_normalize(Address0, Address),
    current_node(Node),
    migration_start(Node),
    (   agent_exists(Node, Name)
    ->  true
    ;   existence_error(agent, Name)
    ),
    new_migration_id(Node, Name, MigId),
    assertz(pending_(Node, MigId)),
    local_node_at(Address, Local),
    transfer(Node, Name, Address, clone, MigId, Clone, Options, Local).

transfer(Node, Name, Address, Mode, MigId, Final, Options, Local) :-
    catch(prepare(Node, Name, Mode, MigId, Address, Options, Local, Record,
                  Tokens, Conn),
          E, ( abort(Node, MigId), throw(E) )),
    hop_probe(prepared),
    catch(hand_over(Node, Conn, Address, Mode, MigId, Name, Record, Tokens,
                    Final, Reuse),
          E2,
          ( transport_discard(Conn), throw(E2) )),
    (   Reuse == true
    ->  transport_release(Conn)
    ;   transport_discard(Conn)
    ).

%   The record that crosses the wire carries no token: the source proves
%   its right to send the agent in the hello (its own tokens and the
%   agent's), and the agent takes the destination's tokens there. A
%   record sent to a node of this process carries, in place of the
%   tokens, same_process(Seal) (code_safety:record_seal/3): its code was
%   trusted here, so it is installed unchecked there.
prepare(Node, Name, Mode, MigId, Address, Options, Local, Record, Tokens,
        Conn) :-
    agent_export(Node, Name, Record0),
    (   Mode == clone
    ->  setarg(1, Record0, rename(Name, Name)),
        setarg(8, Record0, [])
    ;   true
    ),
    arg(4, Record0, AgentTokens),
    setarg(4, Record0, []),
    (   Local \== none
    ->  record_seal(MigId, Record0, Seal),
        setarg(4, Record0, same_process(Seal))
    ;   true
    ),
    Record = Record0,
    node_property(Node, tokens(Own)),
    append(Own, AgentTokens, Tokens0),
    sort(Tokens0, Tokens),
    node_option(Node, connect_timeout, CT),
    node_option(Node, reply_timeout, RT),
    option(connect_timeout(C), Options, CT),
    option(reply_timeout(R), Options, RT),
    transport_acquire(Address, Tokens, Conn,
                      [action(enter), connect_timeout(C), reply_timeout(R)]).

hand_over(Node, Conn, Address, Mode, MigId, Name, Record, Tokens, Final,
          Reuse) :-
    node_property(Node, address(Source)),
    custody_incarnation(Node, Inc),
    get_time(Departed),
    catch(( transport_send(Conn, binary,
                           transfer(MigId, Mode, Source, Departed, Record, Inc)),
            hop_probe(transfer_sent),
            transport_receive(Conn, Reply, [phase(transfer)]),
            hop_probe(answer_read)
          ),
          E,
          ( abort(Node, MigId), throw(E) )),
    (   Reply = ok(staged(Final))
    ->  (   Mode == move
        ->  What = move(Name),
            Leave = remove_departed(Node, Name, MigId)
        ;   What = clone(Final),
            Leave = true
        ),
        catch(custody_commit(Node, MigId, What, Address, Tokens),
              E2, ( abort(Node, MigId), throw(E2) )),
        hop_probe(committed),
        retractall(pending_(Node, MigId)),
        send_commit(Node, Conn, MigId, Leave, Reuse)
    ;   abort(Node, MigId),
        (   Reply = error(error(Formal, _))
        ->  throw(error(Formal, remote(Address)))
        ;   transport_error(Address, protocol(unexpected_reply(Reply)))
        )
    ).

abort(Node, MigId) :-
    custody_decide(Node, MigId, aborted),
    retractall(pending_(Node, MigId)).

%!  remove_departed(+Node, +Name, +MigId) is det.
%
%   Remove the copy of Name that left Node by the committed move MigId,
%   if it is still there (see the module comment).

remove_departed(Node, Name, MigId) :-
    with_custody(Node,
                 (   departing_copy(Node, Name, MigId),
                     custody_decision(Node, MigId, committed)
                 ->  agent_remove(Node, Name)
                 ;   true
                 )).

%   An arriving agent whose name is held here by its own copy that left
%   by a committed move: that copy goes first.
take_back_name(Node, Record) :-
    (   compound(Record),
        compound_name_arity(Record, agent, 8),
        arg(1, Record, Name),
        atom(Name),
        agent_exists(Node, Name),           % usually not: no exception raised
        departing_copy(Node, Name, MigId)
    ->  remove_departed(Node, Name, MigId)
    ;   true
    ).

%   Name is on Node as departing(MigId) (a copy that may go any moment:
%   its absence is a failure, not an error).
departing_copy(Node, Name, MigId) :-
    catch(agent_status(Node, Name, departing(MigId)),
          error(existence_error(agent, _), _), fail).

%   The agent has left whatever happens here (its copy goes once the
%   frame is written, or failed to be); a commit that does not get its
%   answer is sent again by the settle thread.
send_commit(Node, Conn, MigId, Leave, Reuse) :-
    catch(transport_send(Conn, text, commit(MigId)), E, Sent = failed(E)),
    hop_probe(commit_sent),
    catch(Leave, E1, print_message(warning, E1)),   % committed: never restored
    (   var(Sent)
    ->  catch(transport_receive(Conn, Answer, [phase(commit)]), E2, Answer = failed(E2))
    ;   Answer = Sent
    ),
    (   Answer = ok(_)
    ->  custody_acked(Node, MigId),
        Reuse = true
    ;   debug(dfrl(custody), 'commit of ~q not confirmed (~p); settling later',
              [MigId, Answer]),
        Reuse = false
    ).

%!  migration_decision(?Node, ?MigId, ?Decision) is nondet.
%
%   The decision (committed or aborted) a node took as the source of a
%   migration (aborted ones for an hour).

migration_decision(Node, MigId, Decision) :-
    custody_decision(Node, MigId, Decision).

%   For tests that play a source by hand.
decide(Node, MigId, Decision) :-
    custody_decide(Node, MigId, Decision).

		 /*******************************
		 *          DESTINATION		*
		 *******************************/

node:platform_request(transfer(MigId, Mode, Source, Departed, Record, SInc),
                      Ctx, Reply, After) :-
    receive_transfer(Ctx, MigId, Mode, Source, Departed, Record, SInc,
                     Reply, After).
node:platform_request(transfer(MigId, Mode, Source, Departed, Record),
                      Ctx, Reply, After) :-
    receive_transfer(Ctx, MigId, Mode, Source, Departed, Record, none,
                     Reply, After).
node:platform_request(commit(MigId), Ctx, Reply, After) :-
    ctx_node(Ctx, Node),
    (   \+ ctx_authenticated(Ctx)
    ->  unauthenticated(Node, Reply, After)
    ;   migration_start(Node),
        (   custody_staged(Node, Name, MigId, _, _, _),
            activate(Node, Name, MigId)
        ->  Reply = ok(started(Name))
        ;   Reply = ok(not_staged)
        ),
        After = true
    ).
node:platform_request(migration_status(MigId), Ctx, ok(Decision), true) :-
    ctx_node(Ctx, Node),
    migration_start(Node),
    (   pending_(Node, MigId)
    ->  Decision = pending
    ;   custody_decision(Node, MigId, D)
    ->  Decision = D
    ;   custody_incarnation(Node, Inc),
        Decision = unknown(Inc)
    ).

unauthenticated(Node, Reply, close) :-
    node_property(Node, address(Here)),
    Reply = error(error(permission_error(enter, platform, Here),
                        context(_, 'the agent carries no token of this platform'))).

%   An arriving agent's code is checked (code_safety.pl) before anything
%   of it is installed, unless it comes from a node of this process or
%   a peer trusted by name; a refusal is the reply, so the source keeps
%   the agent. It gets this node's tokens, never the ones of a record.
receive_transfer(Ctx, MigId, Mode, Source, Departed, Record0, SInc, Reply, After) :-
    ctx_node(Ctx, Node),
    (   \+ ctx_authenticated(Ctx)
    ->  unauthenticated(Node, Reply, After)
    ;   migration_start(Node),
        must_be(oneof([move, clone]), Mode),
        take_back_name(Node, Record0),
        aggregate_all(count, agent_exists(Node, _), Present),
        bounds_admit(Node, Mode, Present),
        arriving_record(Ctx, Node, MigId, Source, Record0, Record, Peer),
        hop_probe(checked),
        bounds_install(Node, Record, staged(MigId), Name, Peer),
        hop_probe(installed),
        bounds_arrived(Node, Name, Source, Peer),
        get_time(Now),
        catch(custody_stage(Node, Name, MigId, Source, SInc, Now), E,
              ( agent_remove(Node, Name), throw(E) )),
        assertz(arrival_(Node, MigId, Departed)),
        wake_settler_if_due(Node),
        hop_probe(staged),
        Reply = ok(staged(Name)),
        After = true
    ).

%   Peer, for the per-peer bounds (agent_bounds.pl), is `local` for an
%   agent sealed by a node of this process, else the connection's peer
%   (with the Source it claims, on plaintext).
arriving_record(Ctx, Node, MigId, Source, Record0, Record, Peer) :-
    (   compound(Record0), compound_name_arity(Record0, agent, 8)
    ->  true
    ;   throw(error(type_error(agent_record, Record0), _))
    ),
    arg(4, Record0, Seal),
    (   Seal = same_process(S),
        setarg(4, Record0, []),
        record_sealed(MigId, Record0, S)
    ->  Peer = local
    ;   bounds_peer(Ctx, Source, Peer),
        (   code_trusted(Ctx)
        ->  true
        ;   check_agent_record(Record0)
        )
    ),
    node_property(Node, tokens(Tokens)),
    Record0 = agent(Name, Handler, Kind, _, Payload, Preds, Clauses, Hops),
    Record = agent(Name, Handler, Kind, Tokens, Payload, Preds, Clauses, Hops).

%   Start the staged (or in_doubt) agent Name of migration MigId, once.
activate(Node, Name, MigId) :-
    with_custody(Node, activate_(Node, Name, MigId, Source, Departed)),
    hop_probe(activated),
    node_property(Node, link(Link)),
    agent_execute(Node, Name, Link, main),
    hop_probe(dispatched),
    debug(dfrl(custody), '~w: ~q from ~w started', [Node, Name, Source-Departed]).

activate_(Node, Name, MigId, Source, Departed) :-
    agent_status(Node, Name, Status),
    (   Status = staged(MigId) -> true ; Status = in_doubt(MigId, _) ),
    (   custody_staged(Node, Name, MigId, Source, _, Since)
    ->  true
    ;   Status = in_doubt(_, Source), get_time(Since)
    ),
    (   retract(arrival_(Node, MigId, Departed))
    ->  true
    ;   Departed = Since
    ),
    custody_activated(Node, Name, MigId),
    get_time(Arrived),
    format(atom(Here), '~w', [Node]),
    with_agents_locked(
        (   agent_record_hop(Node, Name, hop(Source, Here, Departed, Arrived))
        ->  agent_set_status(Node, Name, idle)
        ;   true
        )).

%   Discard the staged copy of Name: its source decided aborted.
discard(Node, Name, MigId) :-
    with_custody(Node,
                 (   agent_status(Node, Name, Status),
                     ( Status = staged(MigId) ; Status = in_doubt(MigId, _) )
                 ->  agent_remove(Node, Name),
                     custody_unstage(Node, Name),
                     retractall(arrival_(Node, MigId, _))
                 ;   true
                 )).

%!  agent_resolve(+Name, +Decision) is det.
%
%   Settle by hand an agent left in_doubt on the current node (only
%   agents sent by peers without an incarnation stay so): Decision is
%   `start` or `discard`.

agent_resolve(Name, Decision) :-
    must_be(oneof([start, discard]), Decision),
    current_node(Node),
    agent_status(Node, Name, Status),
    (   Status = in_doubt(MigId, _)
    ->  (   Decision == start
        ->  activate(Node, Name, MigId)
        ;   discard(Node, Name, MigId)
        )
    ;   permission_error(resolve, agent, Name)
    ).

		 /*******************************
		 *            SETTLE		*
		 *******************************/

%!  migration_start(+Node) is det.
%
%   Open Node's custody (recovering its store), start its settle thread
%   and restart the recovered agents that were running. Called by the
%   hook node:node_started/1 and on first use; later calls do nothing.

migration_start(Node) :-
    (   settler_(Node, _, _)
    ->  true
    ;   with_mutex(dfrl_migration_start, start_(Node))
    ).

start_(Node) :-
    (   settler_(Node, _, _)
    ->  true
    ;   custody_open(Node, Restart),
        message_queue_create(Queue),
        atom_concat('dfrl_settle@', Node, Alias),
        thread_create(settle_loop(Node, Queue), Tid, [alias(Alias)]),
        assertz(settler_(Node, Tid, Queue)),
        node_property(Node, link(Link)),
        forall(member(Name, Restart),
               catch(agent_execute(Node, Name, Link, main), E,
                     print_message(warning, E)))
    ).

migration_stop(Node) :-
    (   retract(settler_(Node, Tid, Queue))
    ->  thread_send_message(Queue, stop),
        catch(thread_join(Tid, _), _, true),
        message_queue_destroy(Queue)
    ;   true
    ),
    retractall(pending_(Node, _)),
    retractall(arrival_(Node, _, _)),
    custody_close(Node).

wake_settler(Node) :-
    (   settler_(Node, _, Queue)
    ->  thread_send_message(Queue, wake)
    ;   true
    ).

%   A newly staged agent is due after the commit timeout; the settle
%   thread looks again within one period anyway, so it is woken (to wait
%   less) only if the timeout is shorter than the period. A hop then
%   wakes no third thread.
wake_settler_if_due(Node) :-
    custody_option(Node, commit_timeout, 10, CT),
    custody_option(Node, settle_period, 2, Period),
    (   CT < Period
    ->  wake_settler(Node)
    ;   true
    ).

%   thread_get_message/3 fails on timeout: that is a tick, not the end.
settle_loop(Node, Queue) :-
    custody_option(Node, settle_period, 2, Period),
    next_wait(Node, Period, Wait),
    (   thread_get_message(Queue, Msg, [timeout(Wait)])
    ->  true
    ;   Msg = tick
    ),
    (   Msg == stop
    ->  true
    ;   catch(settle_due(Node, Period), E, print_message(warning, E)),
        settle_loop(Node, Queue)
    ).

%   Wake when the first staged agent's commit timeout runs out, at the
%   latest after one period.
next_wait(Node, Period, Wait) :-
    custody_option(Node, commit_timeout, 10, CT),
    get_time(Now),
    findall(W, ( custody_staged(Node, Name, MigId, _, _, Since),
                 agent_status(Node, Name, staged(MigId)),
                 W is max(0.02, Since + CT - Now) ),
            Ws),
    min_list([Period|Ws], Wait).

%!  migration_settle(+Node) is det.
%
%   One settle pass over every staged, in_doubt and unconfirmed
%   hand-over of Node, whatever their age (the settle thread does this
%   for those that are due).

migration_settle(Node) :-
    settle(Node, 0, 0).

settle_due(Node, Period) :-
    custody_option(Node, commit_timeout, 10, CT),
    settle(Node, CT, Period).

settle(Node, StagedAge, CommitAge) :-
    get_time(Now),
    forall(custody_staged(Node, Name, MigId, Source, SInc, Since),
           catch(settle_if_due(Node, Name, MigId, Source, SInc, Now - Since, StagedAge),
                 error(existence_error(agent, Name), _),
                 debug(dfrl(custody), '~w: ~q is gone, nothing to settle', [Node, Name]))),
    forall(( custody_unacked(Node, MigId, Dest, Tokens, Time, _),
             Now - Time >= CommitAge
           ),
           settle_commit(Node, MigId, Dest, Tokens)).

%   An agent that goes away meanwhile (its node stopping, a discard or a
%   start by another path) raises an existence error, which settle/3
%   takes as "nothing to settle".
settle_if_due(Node, Name, MigId, Source, SInc, Age, StagedAge) :-
    agent_status(Node, Name, Status),
    (   Status = in_doubt(MigId, _)
    ->  settle_staged(Node, Name, MigId, Source, SInc)
    ;   Status == staged(MigId), Age >= StagedAge
    ->  settle_staged(Node, Name, MigId, Source, SInc)
    ;   true
    ).

%   The question needs a token proof (node:requires_authentication/1):
%   this node's tokens and the agent's, which its source accepted.
settle_staged(Node, Name, MigId, Source, SInc) :-
    node_option(Node, connect_timeout, CT),
    node_property(Node, tokens(Own)),
    (   agent_property(Node, Name, tokens(Carried)) -> true ; Carried = [] ),
    append(Own, Carried, Tokens0),
    sort(Tokens0, Tokens),
    (   catch(transport_request(Source, migration_status(MigId), Answer,
                                [ tokens(Tokens), connect_timeout(CT),
                                  reply_timeout(CT) ]),
              E, ( debug(dfrl(custody), 'ask ~w: ~p', [Source, E]), fail ))
    ->  true
    ;   Answer = unreachable
    ),
    debug(dfrl(custody), '~w: ~q staged by ~q: source says ~p',
          [Node, Name, MigId, Answer]),
    verdict(Answer, SInc, Verdict),
    apply_verdict(Verdict, Node, Name, MigId, Source).

verdict(committed, _, start) :- !.
verdict(aborted, _, discard) :- !.
verdict(pending, _, wait) :- !.
verdict(unknown(_), none, doubt) :- !.
verdict(unknown(Inc), Inc, discard) :- !.        % presumed abort
verdict(unknown(_), _, start) :- !.              % the source lost its memory
verdict(_, _, doubt).

apply_verdict(start, Node, Name, MigId, _) :-
    ignore(activate(Node, Name, MigId)).
apply_verdict(discard, Node, Name, MigId, _) :-
    discard(Node, Name, MigId).
apply_verdict(wait, _, _, _, _).
apply_verdict(doubt, Node, Name, MigId, Source) :-
    with_custody(Node,
                 (   agent_status(Node, Name, staged(MigId))
                 ->  with_agents_locked(
                         agent_set_status(Node, Name, in_doubt(MigId, Source)))
                 ;   true
                 )).

settle_commit(Node, MigId, Dest, Tokens) :-
    node_option(Node, connect_timeout, CT),
    (   catch(transport_request(Dest, commit(MigId), Answer,
                                [ tokens(Tokens), action(enter),
                                  connect_timeout(CT), reply_timeout(CT) ]),
              E, ( debug(dfrl(custody), 'commit to ~w: ~p', [Dest, E]), fail ))
    ->  debug(dfrl(custody), '~w: commit ~q again: ~p', [Node, MigId, Answer]),
        custody_acked(Node, MigId)
    ;   true
    ).
