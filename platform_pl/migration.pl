:- module(migration,
          [ agent_move/3,               % +Name, +Address, +Options
            agent_clone/4,              % +Name, +Address, -Clone, +Options
            agent_resolve/2,            % +Name, +Decision
            migration_decision/3        % ?Node, ?MigrationId, ?Decision
          ]).
:- use_module(node,
              [ current_node/1, node_property/2, node_option/3,
                node_for_address/2, ctx_node/2, ctx_input/2,
                ctx_authenticated/1 ]).
:- use_module(agents).
:- use_module(transport).
:- use_module(platform_errors, [transport_error/2]).
:- use_module(wire, [frame_read/3]).
:- autoload(library(error),
            [must_be/2, existence_error/2, permission_error/3]).
:- autoload(library(option), [option/2, option/3]).
:- autoload(library(debug), [debug/3]).

/** <module> Weak migration and cloning of agents between nodes

Moving an agent is a two-phase hand-over on one connection:

  1. The source sends transfer(Id, Mode, Source, Departed, Record) as a
     binary frame, after proving the agent's tokens.
  2. The destination checks the tokens and the record, installs the agent
     *staged* (not running) and answers ok(staged(Name)), or refuses.
  3. On that answer the source decides: the migration is committed, the
     agent is removed at the source and commit(Id) is sent. Without that
     answer (refusal, timeout, closed connection) the source decides
     abort and keeps the agent, and move_agent raises the reason.
  4. The destination starts the agent on commit(Id). If the commit does
     not come (lost message, closed connection), it asks the source for
     its decision on Id: committed starts the agent, aborted discards
     the staged copy. If the source cannot be reached the agent is kept
     `in_doubt`, listed and resolvable with agent_resolve/2, never
     silently dropped or started twice.

Each side decides once and records the decision, so one lost message
neither loses nor duplicates an agent.
*/

:- dynamic
    decision/4.                 % Node, MigrationId, Decision, Time

:- multifile node:platform_request/4.

%!  agent_move(+Name, +Address, +Options) is det.
%
%   Move agent Name from the current node to the platform at Address
%   (weak migration: its code and payload travel; at the destination its
%   handler starts again with Event `main`). Succeeds only once the
%   destination has installed the agent; otherwise the agent stays here
%   and the error says why. May be called from the agent's own handler
%   (the usual Tartarus style) or for an idle agent. Options: those of
%   transport_open/3.
%
%   @error existence_error(agent, Name)
%   @error permission_error(move, static_agent, Name)
%   @error permission_error(enter, platform, Address) if the destination
%   refused the agent's tokens.
%   @error transport_error(Address, Reason)

agent_move(Name, Address0, Options) :-
    must_be(atom, Name),
    address_normalize(Address0, Address),
    current_node(Node),
    (   node_for_address(Address, Node)
    ->  move_here(Node, Name)
    ;   with_agents_locked(begin_departure(Node, Name, MigId, Previous)),
        catch(transfer(Node, Name, Address, move, MigId, _Final, Options,
                       agent_remove(Node, Name)),
              E,
              restore_unless_gone(Node, Name, Previous, E))
    ).

%   The move failed. If it failed before the commit the agent is still
%   here: give it back its status. (After the commit it is gone from here
%   and the error is only about sending the commit, which the
%   destination resolves by asking us.)
restore_unless_gone(Node, Name, Previous, E) :-
    (   agent_exists(Node, Name)
    ->  with_agents_locked(agent_set_status(Node, Name, Previous)),
        throw(E)
    ;   print_message(warning, E)
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
    (   agent_exists(Node, Name)
    ->  true
    ;   existence_error(agent, Name)
    ),
    new_migration_id(Node, Name, MigId),
    transfer(Node, Name, Address, clone, MigId, Clone, Options, true).

%   OnCommit runs once the destination has staged the agent and before the
%   commit is sent: the source's copy of a moved agent is gone before the
%   agent can start at the destination (and, e.g., come straight back).
transfer(Node, Name, Address, Mode, MigId, Final, Options, OnCommit) :-
    agent_export(Node, Name, Record0),
    get_time(Departed),
    (   Mode == clone
    ->  setarg(1, Record0, rename(Name, Name)),
        setarg(8, Record0, [])
    ;   true
    ),
    Record = Record0,
    arg(4, Record, Tokens),
    node_property(Node, address(Source)),
    node_option(Node, connect_timeout, CT),
    node_option(Node, reply_timeout, RT),
    merge_timeouts(Options, CT, RT, ConnOptions0),
    ConnOptions = [action(enter)|ConnOptions0],
    transport_acquire(Address, Tokens, Conn, ConnOptions),
    catch(hand_over(Node, Conn, Address, Mode, MigId, Source, Departed,
                    Record, Final, OnCommit),
          E,
          ( transport_discard(Conn), throw(E) )),
    transport_release(Conn).

merge_timeouts(Options, CT, RT, [connect_timeout(C), reply_timeout(R)]) :-
    option(connect_timeout(C), Options, CT),
    option(reply_timeout(R), Options, RT).

hand_over(Node, Conn, Address, Mode, MigId, Source, Departed, Record,
          Final, OnCommit) :-
    catch(( transport_send(Conn, binary,
                           transfer(MigId, Mode, Source, Departed, Record)),
            transport_receive(Conn, Reply, [phase(transfer)])
          ),
          E,
          ( decide(Node, MigId, aborted), throw(E) )),
    (   Reply = ok(staged(Final))
    ->  decide(Node, MigId, committed),
        call(OnCommit),
        transport_send(Conn, binary, commit(MigId))
    ;   decide(Node, MigId, aborted),
        (   Reply = error(error(Formal, _))
        ->  throw(error(Formal, remote(Address)))
        ;   transport_error(Address, protocol(unexpected_reply(Reply)))
        )
    ).

decide(Node, MigId, Decision) :-
    get_time(Now),
    flag(dfrl_decisions, N, N+1),
    (   N mod 512 =:= 0
    ->  prune_decisions(Now)
    ;   true
    ),
    assertz(decision(Node, MigId, Decision, Now)).

prune_decisions(Now) :-
    Old is Now - 3600,
    forall(( decision(N, I, D, T), T < Old ), retract(decision(N, I, D, T))).

%!  migration_decision(?Node, ?MigrationId, ?Decision) is nondet.
%
%   The decision (committed or aborted) a node took as the source of a
%   migration in the last hour.

migration_decision(Node, MigId, Decision) :-
    decision(Node, MigId, Decision, _).

		 /*******************************
		 *          DESTINATION		*
		 *******************************/

node:platform_request(transfer(MigId, Mode, Source, Departed, Record),
                      Ctx, Reply, After) :-
    ctx_node(Ctx, Node),
    (   \+ ctx_authenticated(Ctx)
    ->  node_property(Node, address(Here)),
        Reply = error(error(permission_error(enter, platform, Here),
                            context(_, 'the agent carries no token of this platform'))),
        After = close
    ;   stage(Node, MigId, Mode, Record, Name),
        Reply = ok(staged(Name)),
        After = continue(migration:await_commit(Ctx, MigId, Name, Source,
                                                Departed))
    ).
node:platform_request(migration_status(MigId), Ctx, ok(Decision), true) :-
    ctx_node(Ctx, Node),
    (   decision(Node, MigId, D, _)
    ->  Decision = D
    ;   Decision = unknown
    ).

stage(Node, MigId, Mode, Record, Name) :-
    must_be(oneof([move, clone]), Mode),
    agent_install(Node, Record, staged(MigId), Name).

%!  await_commit(+Ctx, +MigId, +Name, +Source, +Departed) is det.
%
%   Run by the worker after it answered staged: wait for the commit, or
%   ask the source, then start or discard the staged agent.

await_commit(Ctx, MigId, Name, Source, Departed) :-
    ctx_node(Ctx, Node),
    ctx_input(Ctx, In),
    node_option(Node, commit_timeout, Timeout),
    node_option(Node, idle_timeout, Idle),
    set_stream(In, timeout(Timeout)),
    catch(frame_read(In, Frame, [max_size(4096), binary(true)]), _, Frame = lost),
    set_stream(In, timeout(Idle)),
    (   Frame = frame(_, commit(MigId))
    ->  activate(Node, Name, Source, Departed)
    ;   resolve_with_source(Node, MigId, Name, Source, Departed),
        throw(connection_lost)
    ).

resolve_with_source(Node, MigId, Name, Source, Departed) :-
    ask_source(Node, Source, MigId, 3, Decision),
    (   Decision == committed
    ->  activate(Node, Name, Source, Departed)
    ;   Decision == aborted
    ->  agent_remove(Node, Name)
    ;   with_agents_locked(agent_set_status(Node, Name, in_doubt(MigId, Source))),
        print_message(warning, dfrl(agent_in_doubt(Node, Name, Source)))
    ).

ask_source(_, _, _, 0, unreachable) :- !.
ask_source(Node, Source, MigId, Tries, Decision) :-
    node_option(Node, connect_timeout, CT),
    (   catch(transport_request(Source, migration_status(MigId), D,
                                [connect_timeout(CT), reply_timeout(CT)]),
              _, fail),
        D \== unknown
    ->  Decision = D
    ;   Tries1 is Tries - 1,
        sleep(0.2),
        ask_source(Node, Source, MigId, Tries1, Decision)
    ).

activate(Node, Name, Source, Departed) :-
    get_time(Arrived),
    node_property(Node, link(Link)),
    format(atom(Here), '~w', [Node]),
    with_agents_locked(
        (   agent_record_hop(Node, Name, hop(Source, Here, Departed, Arrived))
        ->  agent_set_status(Node, Name, idle)
        ;   true
        )),
    agent_execute(Node, Name, Link, main).

%!  agent_resolve(+Name, +Decision) is det.
%
%   Settle an agent left in_doubt on the current node: Decision is
%   `start` or `discard`.

agent_resolve(Name, Decision) :-
    must_be(oneof([start, discard]), Decision),
    current_node(Node),
    agent_status(Node, Name, Status),
    (   Status = in_doubt(_, Source)
    ->  (   Decision == start
        ->  get_time(Now),
            activate(Node, Name, Source, Now)
        ;   agent_remove(Node, Name)
        )
    ;   permission_error(resolve, agent, Name)
    ).
