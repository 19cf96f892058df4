:- module(migration_arrival,
          [ migration_start/1,          % +Node
            migration_settle/1,         % +Node
            agent_resolve/2,            % +Name, +Decision
            remove_departed/3,          % +Node, +Name, +MigId
            departing_copy/3            % +Node, ?Name, ?MigId
          ]).
:- use_module(node_registry, [current_node/1, node_property/2, node_option/3]).
:- use_module(node_ctx, [ctx_node/2, ctx_authenticated/1]).
:- use_module(agents).
:- use_module(custody).
:- use_module(agent_bounds, [bounds_admit/3, bounds_arrived/4, bounds_install/5,
                              bounds_peer/3]).
:- use_module(transport, [transport_request/4]).
:- use_module(hop_probe, [hop_probe/1]).      % compiled away unless benchmarking
:- use_module(code_safety, [check_agent_record/1, code_trusted/1, record_sealed/3]).
:- autoload(library(aggregate), [aggregate_all/3]).
:- autoload(library(error), [must_be/2, permission_error/3]).
:- autoload(library(debug), [debug/3]).
:- autoload(library(lists), [min_list/2, member/2, append/3]).

/** <module> A hand-over at its destination, and the settle thread

The destination's side of migration.pl's two-phase hand-over (its module
doc has the protocol): a transfer is checked and installed staged, a
commit starts the agent; and the settle thread of every node, which asks
the source of each agent staged too long what it decided and sends again
the commits not yet confirmed. Also the source's copy of a moved agent
that has not gone yet: an arrival of the same agent takes its name back
(remove_departed/3).
*/

:- dynamic
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

%!  departing_copy(+Node, ?Name, ?MigId) is semidet.
%
%   Name is on Node as departing(MigId) (a copy that may go any moment:
%   its absence is a failure, not an error).

departing_copy(Node, Name, MigId) :-
    catch(agent_status(Node, Name, departing(MigId)),
          error(existence_error(agent, _), _), fail).

		 /*******************************
		 *          DESTINATION		*
		 *******************************/

node:platform_request(transfer(MigId, Mode, Source, Departed, Record, SInc),
                      Ctx, Reply, After) :-
    receive_transfer(Ctx, transfer(MigId, Mode, Source, Departed, Record, SInc),
                     Reply, After).
node:platform_request(transfer(MigId, Mode, Source, Departed, Record),
                      Ctx, Reply, After) :-
    receive_transfer(Ctx, transfer(MigId, Mode, Source, Departed, Record, none),
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
unauthenticated(Node, Reply, close) :-
    node_property(Node, address(Here)),
    Reply = error(error(permission_error(enter, platform, Here),
                        context(_, 'the agent carries no token of this platform'))).

%   An arriving agent's code is checked (code_safety.pl) before anything
%   of it is installed, unless it comes from a node of this process or
%   a peer trusted by name; a refusal is the reply, so the source keeps
%   the agent. It gets this node's tokens, never the ones of a record.
%   Transfer is transfer(MigId, Mode, Source, Departed, Record, SInc), SInc
%   `none` from a peer that sends no incarnation.
receive_transfer(Ctx, Transfer, Reply, After) :-
    Transfer = transfer(MigId, Mode, Source, Departed, Record0, SInc),
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
