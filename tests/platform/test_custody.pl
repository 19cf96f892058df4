/*  plunit tests of custody in one process (several nodes on OS-chosen
    localhost ports): the verdicts a destination draws from its source's
    answer, stores, recovery, census. The multi-process cases (kill -9,
    SIGSTOP, proxies) are in test_custody.py.
    Run: swipl -g run_tests -t halt test_custody.pl
*/
:- use_module('../../platform_pl/tartarus').
:- use_module('../../platform_pl/transport').
:- use_module('../../platform_pl/custody').
:- use_module(library(plunit)).
:- use_module(library(filesex)).

:- dynamic parcel/3, arrivals/2, user:arrived/2.

arrivals(guid, 0).
parcel(guid, _Link, main) :-
    retract(arrivals(guid, N0)), N is N0 + 1, assertz(arrivals(guid, N)),
    assertz(user:arrived(guid, N)).

%   Up to 15 s: these tests assert what happens, not how fast (a settle pass every 0.2 s
%   is quick on an idle machine; 4 s was once too short under a full test run's load).
wait_for(Goal) :- wait_for(Goal, 750).
wait_for(Goal, N) :-
    (   call(Goal) -> true
    ;   N > 0 -> sleep(0.02), N1 is N - 1, wait_for(Goal, N1)
    ;   fail
    ).

opts([token(k), default(false), connect_timeout(1), commit_timeout(0.3),
      settle_period(0.2)]).

start(Node, Extra) :-
    opts(O0), append(Extra, O0, O),
    node_start(localhost:0, Node, O),
    migration:migration_start(Node).

stop_all(Nodes) :- forall(member(N, Nodes), catch(node_stop(N), _, true)).

census(Node, L) :- custody_agents(Node, L).

%   Play a source by hand: send transfer/6 with incarnation Inc, take the
%   staged answer, close without a commit.
transfer_by_hand(Src, Dst, Name, MigId, Inc) :-
    agents:agent_export(Src, Name, Record),
    setarg(4, Record, []),                      % sealed as a node of this process does
    code_safety:record_seal(MigId, Record, Seal),
    setarg(4, Record, same_process(Seal)),
    node_property(Src, address(SrcAddr)),
    node_property(Dst, address(DstAddr)),
    get_time(T),
    transport_open(DstAddr, Conn, []),
    transport_auth(Conn, [k], enter),
    transport_send(Conn, binary, transfer(MigId, move, SrcAddr, T, Record, Inc)),
    transport_receive(Conn, Reply, []),
    transport_close(Conn),
    assertion(Reply = ok(staged(Name))).

parcel_on(Node, Name) :-
    with_node(Node, ( create_mobile_agent(Name, parcel, [k]),
                      add_payload(Name, [(arrivals,2)]) )).

:- begin_tests(verdicts, [cleanup(retractall(user:arrived(_, _)))]).

test(presumed_abort_same_incarnation, [cleanup(stop_all([A,B]))]) :-
    start(A, []), start(B, []),
    parcel_on(A, v1),
    custody_incarnation(A, Inc),
    transfer_by_hand(A, B, v1, m1, Inc),          % A has no record of m1
    assertion(wait_for(( census(B, L), L == [] ))),
    census(A, LA),
    assertion(LA == [agent(v1, idle)]).

test(source_lost_its_memory, [cleanup(stop_all([A,B]))]) :-
    start(A, []), start(B, []),
    parcel_on(A, v2),
    transfer_by_hand(A, B, v2, m2, 'an-incarnation-that-died'),
    assertion(wait_for(user:arrived(v2, 1))),     % B holds the only copy: started
    assertion(wait_for(( census(B, L), L == [agent(v2, idle)] ))).

test(pending_source_is_waited_for, [cleanup(stop_all([A,B]))]) :-
    start(A, []), start(B, []),
    parcel_on(A, v3),
    custody_incarnation(A, Inc),
    assertz(migration:pending_(A, m3)),
    transfer_by_hand(A, B, v3, m3, Inc),
    sleep(1.0),
    census(B, L1),
    assertion(L1 == [agent(v3, staged)]),         % asked, told pending, kept
    retract(migration:pending_(A, m3)),
    migration:decide(A, m3, committed),
    assertion(wait_for(user:arrived(v3, 1))).

test(unreachable_source_in_doubt_then_settled, [cleanup(stop_all([A,B]))]) :-
    start(A, []), start(B, []),
    parcel_on(A, v4),
    custody_incarnation(A, Inc),
    transfer_by_hand(A, B, v4, m4, Inc),
    node_property(A, address(_:PA)),
    node_stop(A),                                 % nobody answers for the source
    assertion(wait_for(( census(B, L), L == [agent(v4, in_doubt)] ))),
    start_on(PA, A2),                             % a source again, with no record
    custody_incarnation(A2, Inc2),
    assertion(Inc2 \== Inc),                      % without a store: a new memory
    assertion(wait_for(user:arrived(v4, 1))),
    stop_all([A2]).

start_on(Port, Node) :-
    opts(O),
    node_start(localhost:Port, Node, O),
    migration:migration_start(Node).

:- end_tests(verdicts).

%   The complete agent files of a store (not the temporary ones of a write
%   in progress).
files(Store, Files) :-
    directory_file_path(Store, 'custody/agents', Dir),
    directory_files(Dir, All),
    exclude([F]>>( sub_atom(F, 0, _, _, '.') ; file_name_extension(_, tmp, F) ), All, Files).

%   The agent in a store with one agent file rests (its handler returned).
resting(Store, Name) :-
    files(Store, [F]),
    directory_file_path(Store, 'custody/agents', Dir),
    directory_file_path(Dir, F, File),
    catch(custody_store:store_read(File, custody_agent(Name, active(idle), _, _)), _, fail).

decisions(Store, Files) :-
    directory_file_path(Store, 'custody/decisions', Dir),
    directory_files(Dir, All),
    exclude([F]>>sub_atom(F, 0, _, _, '.'), All, Files).

:- begin_tests(store, [cleanup(retractall(user:arrived(_, _)))]).

test(move_with_stores_leaves_one_file, [cleanup((stop_all([A,B]), delete_directory_and_contents(D)))]) :-
    tmp_file(custody, D),
    directory_file_path(D, a, DA), directory_file_path(D, b, DB),
    start(A, [store(DA)]), start(B, [store(DB)]),
    parcel_on(A, s1),
    files(DA, FA0), assertion(length(FA0, 1)),
    node_property(B, address(BA)),
    with_node(A, agent_move(s1, BA, [])),
    assertion(wait_for(user:arrived(s1, 1))),
    assertion(wait_for(( files(DA, FA), FA == [] ))),
    assertion(wait_for(resting(DB, s1))),
    decisions(DA, Dec), assertion(Dec == []).     % confirmed, forgotten

%   The source removes its copy of a moved agent only after writing the
%   commit frame. Staged here by hand: A's copy of c1 left by the committed
%   move m9 (departing, decided) and is still registered when c1 comes
%   straight back from B. The arrival must take the name back, and A's
%   late removal must then leave the new copy and its custody file alone.
test(arrival_takes_back_a_name_its_departed_copy_holds,
     [cleanup((stop_all([A,B]), delete_directory_and_contents(D)))]) :-
    tmp_file(custody, D),
    directory_file_path(D, a, DA),
    start(A, [store(DA)]), start(B, []),
    parcel_on(A, c1),
    parcel_on(B, c1),
    node_property(B, address(BA)),
    agents:with_agents_locked(agents:agent_set_status(A, c1, departing(m9))),
    custody_commit(A, m9, move(c1), BA, [k]),
    node_property(A, address(AA)),
    with_node(B, agent_move(c1, AA, [])),         % refused before: the name was taken
    assertion(wait_for(user:arrived(c1, 1))),
    migration:remove_departed(A, c1, m9),         % A's own thread, late
    assertion(agents:agent_exists(A, c1)),
    assertion(\+ agents:agent_status(A, c1, departing(_))),
    assertion(wait_for(resting(DA, c1))).

%   A move that raises after its commit decision (a signal between the
%   decision and the removal of the copy) must not bring the copy back to
%   life: the agent runs at its destination. Control: the same call on a
%   move that was not committed restores the agent.
test(committed_copy_is_never_restored, [cleanup(stop_all([A]))]) :-
    start(A, []),
    parcel_on(A, r8), parcel_on(A, r9),
    agents:with_agents_locked(agents:agent_set_status(A, r9, departing(m7))),
    custody_commit(A, m7, move(r9), 'localhost:1', [k]),
    agents:with_agents_locked(migration:restore(A, r9, m7, idle, Left)),
    assertion(Left == true),
    assertion(agents:agent_status(A, r9, departing(m7))),
    migration:remove_departed(A, r9, m7),
    assertion(\+ agents:agent_exists(A, r9)),
    agents:with_agents_locked(agents:agent_set_status(A, r8, departing(m6))),
    agents:with_agents_locked(migration:restore(A, r8, m6, idle, Left8)),
    assertion(Left8 == false),
    assertion(agents:agent_status(A, r8, idle)).

test(restart_recovers_agents, [cleanup((stop_all([B2]), delete_directory_and_contents(D)))]) :-
    tmp_file(custody, D),
    start(B, [store(D)]),
    parcel_on(B, r1),
    node_property(B, link(Link)),
    with_node(B, execute_agent(r1, Link, parcel)),
    assertion(wait_for(user:arrived(r1, 1))),
    assertion(wait_for(resting(D, r1))),
    node_property(B, address(_:P)),
    node_stop(B),
    opts(O),
    node_start(localhost:P, B2, [store(D)|O]),
    migration:migration_start(B2),
    assertion(wait_for(( census(B2, L), L == [agent(r1, idle)] ))),
    agent_property(B2, r1, module(M)),
    assertion(M:arrivals(r1, 1)).

test(store_write_reads_back, [setup(tmp_file(store, Dir)), cleanup(delete_directory_and_contents(Dir))]) :-
    make_directory(Dir),
    directory_file_path(Dir, 'a.term', File),
    custody_store:store_write(File, t([1.5, 'x y'], "s")),
    custody_store:store_write(File, t(2)),
    assertion(custody_store:store_read(File, t(2))),
    atom_concat(File, '.tmp', Tmp),
    assertion(\+ exists_file(Tmp)).

%   The binary format: a term with variables, floats and non-ASCII text
%   comes back as written; a file of an older store (one canonical text
%   term) is still read.
test(store_binary_and_text, [setup(tmp_file(store, Dir)), cleanup(delete_directory_and_contents(Dir))]) :-
    make_directory(Dir),
    directory_file_path(Dir, 'c.term', File),
    T = t([1.5, 0.25], 'ünï', "s", X, f(X, _)),
    custody_store:store_write(File, T),
    custody_store:store_read(File, T1),
    assertion(T1 =@= T),
    setup_call_cleanup(open(File, write, Out, [encoding(utf8)]),
                       format(Out, '~k.~n', [old('ünï', [1.5])]),
                       close(Out)),
    assertion(custody_store:store_read(File, old('ünï', [1.5]))).

%   A byte changed after the header is found by the checksum before the
%   fast-term decoder (which trusts its input) sees it; a short file is
%   truncated.
test(store_corrupt_file_refused, [setup(tmp_file(store, Dir)), cleanup(delete_directory_and_contents(Dir))]) :-
    make_directory(Dir),
    directory_file_path(Dir, 'd.term', File),
    custody_store:store_write(File, t(abc, [1, 2, 3])),
    read_file_to_codes(File, Codes, [type(binary)]),
    length(Codes, N),
    Last is N - 2,
    length(Prefix, Last),
    once(append(Prefix, [_|Rest], Codes)),
    append(Prefix, [0'Z|Rest], Bad),
    setup_call_cleanup(open(File, write, O1, [type(binary)]),
                       format(O1, "~s", [Bad]), close(O1)),
    catch(custody_store:store_read(File, _), E1, true),
    assertion(E1 = error(io_error(read, File), context(_, corrupt(checksum)))),
    once(append(Short, [_, _], Codes)),
    setup_call_cleanup(open(File, write, O2, [type(binary)]),
                       format(O2, "~s", [Short]), close(O2)),
    catch(custody_store:store_read(File, _), E2, true),
    assertion(E2 = error(io_error(read, File), context(_, corrupt(truncated)))).

test(fsync_of_a_missing_file_is_an_io_error) :-
    catch(custody_store:fsync('/nonexistent/dfrl/x'), E, true),
    assertion(nonvar(E)).

%   Where the helper cannot run, coreutils sync does the fsync.
test(fsync_without_the_helper, [setup(tmp_file(store, Dir)), cleanup(delete_directory_and_contents(Dir))]) :-
    make_directory(Dir),
    directory_file_path(Dir, 'b.term', File),
    setup_call_cleanup(
        assertz(custody_store:fsync_helper_failed_),
        ( with_mutex(dfrl_fsync, custody_store:helper_died),
          custody_store:store_write(File, t(3)) ),
        retractall(custody_store:fsync_helper_failed_)),
    assertion(custody_store:store_read(File, t(3))).

:- end_tests(store).
