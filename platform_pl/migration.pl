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
              [ current_node/1, node_property/2, node_option/3, node_for_address/2,
                ctx_node/2 ]).
:- use_module(agents).
:- use_module(custody).
:- use_module(transport).
:- use_module(hop_probe, [hop_probe/1]).      % compiled away unless benchmarking
:- use_module(platform_errors, [transport_error/2]).
:- use_module(code_safety, [record_seal/3]).
:- use_module(migration_arrival,
              [ migration_start/1, migration_settle/1, agent_resolve/2,
                remove_departed/3, departing_copy/3 ]).
:- autoload(library(error), [must_be/2, existence_error/2, permission_error/3]).
:- autoload(library(option), [option/2, option/3]).
:- autoload(library(debug), [debug/3]).
:- autoload(library(lists), [append/3]).

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

This module is the source's side; the destination's side and the settle
thread are migration_arrival.pl's (migration_start/1,
migration_settle/1 and agent_resolve/2 are re-exported here).

A hop in the making is the term hop(Node, Name, Address, Mode, MigId):
this node, the agent, where it goes, `move` or `clone`, the migration.
*/

:- dynamic
    pending_/2.                 % Node, MigId

:- multifile
    node:platform_request/4,
    node:node_stopping/1.

node:node_stopping(Node) :-
    retractall(pending_(Node, _)).

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
        catch(transfer(hop(Node, Name, Address, move, MigId), _Final, Options, Local),
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
    transfer(hop(Node, Name, Address, clone, MigId), Clone, Options, Local).

transfer(Hop, Final, Options, Local) :-
    Hop = hop(Node, _, _, _, MigId),
    catch(prepare(Hop, Options, Local, Record, Tokens, Conn),
          E, ( abort(Node, MigId), throw(E) )),
    hop_probe(prepared),
    catch(hand_over(Hop, Conn, Record, Tokens, Final, Reuse),
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
prepare(hop(Node, Name, Address, Mode, MigId), Options, Local, Record, Tokens, Conn) :-
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

hand_over(hop(Node, Name, Address, Mode, MigId), Conn, Record, Tokens, Final, Reuse) :-
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

