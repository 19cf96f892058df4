:- module(custody,
          [ custody_open/2,             % +Node, -ToRestart
            custody_close/1,            % +Node
            custody_agents/2,           % +Node, -Agents
            custody_incarnation/2,      % +Node, -Incarnation
            custody_decide/3,           % +Node, +MigId, +Decision
            custody_commit/5,           % +Node, +MigId, +What, +Dest, +Tokens
            custody_decision/3,         % ?Node, ?MigId, ?Decision
            custody_unacked/6,          % ?Node, ?MigId, ?Dest, ?Tokens, ?Time, ?Name
            custody_acked/2,            % +Node, +MigId
            custody_stage/6,            % +Node, +Name, +MigId, +Source, +SourceInc, +Since
            custody_staged/6,           % ?Node, ?Name, ?MigId, ?Source, ?SourceInc, ?Since
            custody_unstage/2,          % +Node, +Name
            custody_activated/3,        % +Node, +Name, +MigId
            custody_option/4,           % +Node, +Name, +Default, -Value
            custody_take_recovered/2,   % +Node, +Name
            with_custody/2              % +Node, :Goal
          ]).
:- use_module(node, [node_option/3, ctx_node/2]).
:- use_module(agents,
              [ agent_exists/2, agent_export/3, agent_install/4, agent_status/3,
                agent_list/2 ]).
:- use_module(custody_store).
:- autoload(library(filesex), [directory_file_path/3]).
:- autoload(library(lists), [member/2]).
:- autoload(library(error), [must_be/2]).

:- meta_predicate
    with_custody(+, 0).

/** <module> Custody of agents: what a node holds and what it decided, durably

This module keeps, per node, the state that the hand-over protocol of
migration.pl needs to survive a kill -9 and a restart:

  - the *decisions* the node took as the source of a migration. Only
    `committed` decisions are kept durably (with the destination and the
    agent's tokens), until the destination confirms it started the
    agent; `aborted` is kept in memory for an hour and is also the
    answer for any migration the node has no record of (presumed
    abort, see migration.pl);
  - every agent the node *holds*: active (idle or running) or staged
    (arrived, waiting for its source's decision), one file per agent.

With the node option `store(Dir)` these live under `Dir/custody/`
(`agents/`, `decisions/`, `incarnation`), each file replaced atomically
by custody_store.pl (temp, fsync, rename, fsync of the directory).
Without a store the same state is kept in memory only.

An agent's file holds custody_agent(Name, State, Via, Record):
State is active(idle|run) or staged(MigId, Source, SourceInc, Since);
Via is the migration it arrived by (or created(Id)), so that a
committed decision about an *older* copy never deletes a copy that came
back later. A decision's file holds
custody_decision(MigId, Name, Dest, Tokens, Via, Time).

Recovery (custody_open/2, at node start):

  - a committed decision is loaded as committed and unacknowledged;
  - an agent file whose Name and Via match a committed decision is a
    copy that left (the crash fell between writing the decision and
    deleting the file): it is deleted;
  - an active agent is installed idle; if it was running it is
    returned in ToRestart (weak migration: its handler starts again
    with `main`) and noted as recovered: custody_take_recovered/2 tells
    its handler, once, that it starts from the store, not from an
    arrival (the dFRL agent then asks its holder whether it was
    resurrected elsewhere meanwhile before it does anything);
  - a staged agent is installed staged; the settle thread of
    migration.pl asks its source at once.

The incarnation is an id of the node's memory: stored in the store (so
it survives restarts with the store) or made fresh at each start
without one. A destination compares it to tell "the source has no
record because it never committed" from "the source restarted without
its memory".

Agents change through agents.pl, which calls the hook
agents:agent_changed/3 (saved, run(Flag), removed); the clauses here
rewrite or delete the agent's file under the node's custody mutex.
*/

:- dynamic
    store_dir_/2,               % Node, CustodyDir
    incarnation_/2,             % Node, Id
    decision_/4,                % Node, MigId, Decision, Time
    commit_info_/6,             % Node, MigId, Name, Dest, Tokens, Via
    staged_/6,                  % Node, Name, MigId, Source, SourceInc, Since
    via_/3,                     % Node, Name, Via
    run_flag_/3,                % Node, Name, idle|run
    recovered_/2,               % Node, Name: restarted from the store
    opened_/1.                  % Node

:- multifile agents:agent_changed/3.

%!  with_custody(+Node, :Goal) is semidet.
%
%   Run Goal holding Node's custody mutex (recursive). Every change of
%   a custody file and the in-memory state it mirrors happens inside.

with_custody(Node, Goal) :-
    atom_concat('dfrl_custody@', Node, Mutex),
    with_mutex(Mutex, Goal).

%!  custody_option(+Node, +Name, +Default, -Value) is det.
%
%   The node option Name, or Default if the node does not have it.

custody_option(Node, Name, Default, Value) :-
    (   catch(node_option(Node, Name, V), _, fail),
        V \== none
    ->  Value = V
    ;   Value = Default
    ).

		 /*******************************
		 *        OPEN / RECOVER		*
		 *******************************/

%!  custody_open(+Node, -ToRestart) is det.
%
%   Open Node's custody state (once; later calls give []): read the
%   store if the node has one and recover the agents and decisions in
%   it. ToRestart lists the recovered agents that were running.

custody_open(Node, ToRestart) :-
    with_mutex(custody_open,
               (   opened_(Node)
               ->  ToRestart = []
               ;   with_custody(Node, open_(Node, ToRestart)),
                   assertz(opened_(Node))
               )).

open_(Node, ToRestart) :-
    (   custody_option(Node, store, none, Dir0)
    ->  true
    ;   Dir0 = none
    ),
    (   Dir0 == none
    ->  fresh_id(Inc),
        assertz(incarnation_(Node, Inc)),
        ToRestart = []
    ;   absolute_file_name(Dir0, Dir1),
        directory_file_path(Dir1, custody, Dir),
        directory_file_path(Dir, agents, AgentDir),
        directory_file_path(Dir, decisions, DecDir),
        store_make_dirs(AgentDir),
        store_make_dirs(DecDir),
        assertz(store_dir_(Node, Dir)),
        open_incarnation(Node, Dir),
        store_terms(DecDir, Decisions),
        forall(member(_-D, Decisions), recover_decision(Node, D)),
        store_terms(AgentDir, Agents),
        findall(Name,
                ( member(File-A, Agents),
                  recover_agent(Node, File, A, Name)
                ),
                ToRestart)
    ).

open_incarnation(Node, Dir) :-
    directory_file_path(Dir, incarnation, File),
    (   store_read(File, custody_incarnation(Inc))
    ->  true
    ;   fresh_id(Inc),
        store_write(File, custody_incarnation(Inc))
    ),
    assertz(incarnation_(Node, Inc)).

fresh_id(Id) :-
    A is random(1<<62),
    B is random(1<<62),
    format(atom(Id), '~16r~16r', [A, B]).

recover_decision(Node, custody_decision(MigId, Name, Dest, Tokens, Via, Time)) :-
    !,
    assertz(decision_(Node, MigId, committed, Time)),
    assertz(commit_info_(Node, MigId, Name, Dest, Tokens, Via)).
recover_decision(_, Term) :-
    print_message(warning, format('custody: not a decision: ~p', [Term])).

%   recover_agent(+Node, +File, +Term, -Name) succeeds for an agent to
%   restart.
recover_agent(Node, File, custody_agent(Name, State, Via, Record), Restart) :-
    !,
    (   commit_info_(Node, _, Name, _, _, Via)
    ->  store_delete(File),
        fail
    ;   State = active(Flag)
    ->  catch(agent_install(Node, Record, idle, Name), E,
              ( print_message(warning, E), fail )),
        assertz(via_(Node, Name, Via)),
        assertz(run_flag_(Node, Name, Flag)),
        Flag == run,
        assertz(recovered_(Node, Name)),
        Restart = Name
    ;   State = staged(MigId, Source, SInc, Since)
    ->  catch(agent_install(Node, Record, staged(MigId), Name), E,
              ( print_message(warning, E), fail )),
        assertz(via_(Node, Name, MigId)),
        assertz(staged_(Node, Name, MigId, Source, SInc, Since)),
        fail
    ).
recover_agent(_, File, Term, _) :-
    print_message(warning, format('custody: ~w does not hold an agent: ~p', [File, Term])),
    fail.

%!  custody_close(+Node) is det.
%
%   Forget Node's in-memory custody state (its store stays as it is).

custody_close(Node) :-
    with_custody(Node,
                 ( retractall(store_dir_(Node, _)),
                   retractall(incarnation_(Node, _)),
                   retractall(decision_(Node, _, _, _)),
                   retractall(commit_info_(Node, _, _, _, _, _)),
                   retractall(staged_(Node, _, _, _, _, _)),
                   retractall(via_(Node, _, _)),
                   retractall(run_flag_(Node, _, _)),
                   retractall(recovered_(Node, _)),
                   retractall(opened_(Node))
                 )).

%!  custody_take_recovered(+Node, +Name) is semidet.
%
%   True, once, if Name was restarted on Node from its store
%   (custody_open/2 returned it to restart) and has not been asked yet.

custody_take_recovered(Node, Name) :-
    with_custody(Node, retract(recovered_(Node, Name))).

%!  custody_incarnation(+Node, -Inc) is det.

custody_incarnation(Node, Inc) :-
    (   incarnation_(Node, Inc0)
    ->  Inc = Inc0
    ;   custody_open(Node, _),
        incarnation_(Node, Inc)
    ).

		 /*******************************
		 *           DECISIONS		*
		 *******************************/

%!  custody_decide(+Node, +MigId, +Decision) is det.
%
%   Record a decision in memory (aborted; or committed for a clone-free
%   test). Durable commits go through custody_commit/5.

custody_decide(Node, MigId, Decision) :-
    must_be(oneof([committed, aborted]), Decision),
    get_time(Now),
    flag(dfrl_decisions, N, N+1),
    (   N mod 512 =:= 0
    ->  prune_decisions(Now)
    ;   true
    ),
    assertz(decision_(Node, MigId, Decision, Now)).

%   Aborted decisions, and committed ones the destination confirmed, are
%   forgotten after an hour (presumed abort answers the same for the
%   first; nobody asks about the second).
prune_decisions(Now) :-
    Old is Now - 3600,
    forall(( decision_(N, I, D, T), T < Old,
             \+ commit_info_(N, I, _, _, _, _) ),
           retract(decision_(N, I, D, T))).

%!  custody_commit(+Node, +MigId, +What, +Dest, +Tokens) is det.
%
%   Decide committed for MigId, durably if Node has a store. What is
%   move(Name) (the copy of Name held here leaves: migration.pl removes
%   it once the commit frame is written) or clone(Name) (Name stays).
%   The decision is kept until custody_acked/2.
%
%   @error the file system's error if the decision cannot be written;
%   then nothing was decided.

custody_commit(Node, MigId, What, Dest, Tokens) :-
    with_custody(Node, commit_(Node, MigId, What, Dest, Tokens)).

commit_(Node, MigId, What, Dest, Tokens) :-
    get_time(Now),
    (   What = move(Name),
        via_(Node, Name, Via0)
    ->  Via = Via0
    ;   arg(1, What, Name),
        Via = none
    ),
    (   store_dir_(Node, Dir)
    ->  decision_file(Dir, MigId, File),
        store_write(File, custody_decision(MigId, Name, Dest, Tokens, Via, Now))
    ;   true
    ),
    assertz(decision_(Node, MigId, committed, Now)),
    assertz(commit_info_(Node, MigId, Name, Dest, Tokens, Via)).

%!  custody_decision(?Node, ?MigId, ?Decision) is nondet.

custody_decision(Node, MigId, Decision) :-
    decision_(Node, MigId, Decision, _).

%!  custody_unacked(?Node, ?MigId, ?Dest, ?Tokens, ?Time, ?Name) is nondet.
%
%   Committed decisions (taken at Time) whose destination has not yet
%   confirmed.

custody_unacked(Node, MigId, Dest, Tokens, Time, Name) :-
    commit_info_(Node, MigId, Name, Dest, Tokens, _),
    decision_(Node, MigId, committed, Time).

%!  custody_acked(+Node, +MigId) is det.
%
%   The destination of MigId confirmed it holds the agent as active (or
%   never had it): forget the durable decision. It stays in memory as
%   committed for an hour, for late questions.

custody_acked(Node, MigId) :-
    with_custody(Node,
                 (   retract(commit_info_(Node, MigId, _, _, _, _))
                 ->  (   store_dir_(Node, Dir)
                     ->  decision_file(Dir, MigId, File),
                         store_delete(File)
                     ;   true
                     )
                 ;   true
                 )).

decision_file(Dir, MigId, File) :-
    directory_file_path(Dir, decisions, DecDir),
    store_key_file(DecDir, MigId, term, File).

		 /*******************************
		 *        HELD AGENTS		*
		 *******************************/

agent_file(Node, Name, File) :-
    store_dir_(Node, Dir),
    directory_file_path(Dir, agents, AgentDir),
    store_key_file(AgentDir, Name, term, File).

%!  custody_stage(+Node, +Name, +MigId, +Source, +SourceInc, +Since) is det.
%
%   Agent Name (installed staged(MigId)) is held durably as staged,
%   before the destination answers `staged`.

custody_stage(Node, Name, MigId, Source, SInc, Since) :-
    with_custody(Node,
                 ( write_agent(Node, Name, staged(MigId, Source, SInc, Since), MigId),
                   retractall(via_(Node, Name, _)),
                   assertz(via_(Node, Name, MigId)),
                   retractall(run_flag_(Node, Name, _)),
                   retractall(staged_(Node, Name, _, _, _, _)),
                   assertz(staged_(Node, Name, MigId, Source, SInc, Since))
                 )).

%!  custody_staged(?Node, ?Name, ?MigId, ?Source, ?SourceInc, ?Since) is nondet.

custody_staged(Node, Name, MigId, Source, SInc, Since) :-
    staged_(Node, Name, MigId, Source, SInc, Since).

%!  custody_unstage(+Node, +Name) is det.
%
%   Forget the staging facts of Name (its file goes with agent_remove/2).

custody_unstage(Node, Name) :-
    retractall(staged_(Node, Name, _, _, _, _)).

%!  custody_activated(+Node, +Name, +MigId) is det.
%
%   The staged agent Name becomes active (about to run): held durably
%   as active(run), arrived by MigId.

custody_activated(Node, Name, MigId) :-
    with_custody(Node,
                 ( write_agent(Node, Name, active(run), MigId),
                   retractall(run_flag_(Node, Name, _)),
                   assertz(run_flag_(Node, Name, run)),
                   retractall(staged_(Node, Name, _, _, _, _))
                 )).

write_agent(Node, Name, State, Via) :-
    (   agent_file(Node, Name, File)
    ->  agent_export(Node, Name, Record),
        store_write(File, custody_agent(Name, State, Via, Record))
    ;   true
    ).

agents:agent_changed(Event, Node, Name) :-
    (   opened_(Node)
    ->  with_custody(Node, changed(Event, Node, Name))
    ;   true
    ).

changed(removed, Node, Name) :-
    (   agent_file(Node, Name, File)
    ->  store_delete(File)
    ;   true
    ),
    retractall(via_(Node, Name, _)),
    retractall(run_flag_(Node, Name, _)),
    retractall(staged_(Node, Name, _, _, _, _)).
changed(saved, Node, Name) :-
    save_active(Node, Name).
changed(run(Flag), Node, Name) :-
    (   run_flag_(Node, Name, Flag)
    ->  true
    ;   retractall(run_flag_(Node, Name, _)),
        assertz(run_flag_(Node, Name, Flag)),
        save_active(Node, Name)
    ).

%   An active agent's file is rewritten with its current state; staged
%   and in-doubt agents keep their staged file until their decision.
save_active(Node, Name) :-
    (   agent_exists(Node, Name),
        agent_status(Node, Name, Status),
        \+ Status = staged(_),
        \+ Status = in_doubt(_, _),
        agent_file(Node, Name, _)
    ->  (   via_(Node, Name, Via)
        ->  true
        ;   fresh_id(Id),
            Via = created(Id),
            assertz(via_(Node, Name, Via))
        ),
        (   run_flag_(Node, Name, Flag)
        ->  true
        ;   Flag = idle
        ),
        write_agent(Node, Name, active(Flag), Via)
    ;   true
    ).

		 /*******************************
		 *            CENSUS		*
		 *******************************/

%!  custody_agents(+Node, -Agents) is det.
%
%   Agents lists agent(Name, Status) for every agent Node holds, Status
%   one of running, idle, staged, departing, in_doubt.

custody_agents(Node, Agents) :-
    agent_list(Node, List),
    findall(agent(Name, Status),
            ( member(agent(Name, _, _, S0), List),
              census_status(S0, Status)
            ),
            Agents).

census_status(running, running) :- !.
census_status(starting, running) :- !.
census_status(in_doubt(_, _), in_doubt) :- !.
census_status(S, S).

:- multifile node:platform_request/4.

node:platform_request(custody_agents, Ctx, ok(Agents), true) :-
    ctx_node(Ctx, Node),
    custody_agents(Node, Agents).
