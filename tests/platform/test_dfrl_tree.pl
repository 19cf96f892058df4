/*  plunit tests of the dFRL agent's tree itinerary (dfrl_tree.pl) on
    in-process nodes, robots with in-memory tables (memory_robots.pl). Each
    tree round is checked against what a chain round gives from the same
    tables (aggregate_tables/3 folds them in itinerary order, as the chain's
    forward pass does), bit for bit.
*/
:- use_module('../../platform_pl/tartarus').
:- use_module('../../platform_pl/dfrl_agent/dfrl_agent').
:- use_module('../../platform_pl/dfrl_agent/dfrl_tree',
              [tree_children/4, tree_subtree/4]).
:- use_module(memory_robots).
:- use_module('../../platform_pl/node', [local_node/1]).
:- use_module(library(plunit)).
:- use_module(library(http/json)).

:- dynamic quiet/0.
:- multifile user:message_hook/3.
:- dynamic user:message_hook/3.
:- asserta((user:message_hook(_, warning, _) :- quiet)).
:- asserta((user:message_hook(_, error, _) :- quiet)).

% a method whose result depends on the order of the tables: the first one
:- multifile dfrl_aggregation:aggregate_init/3, dfrl_aggregation:aggregate_step/4,
             dfrl_aggregation:aggregate_final/3.
dfrl_aggregation:aggregate_init(first_table, qtable(_, V), V).
dfrl_aggregation:aggregate_step(first_table, A, _, A).
dfrl_aggregation:aggregate_final(first_table, A, A).
% a method whose step fails
dfrl_aggregation:aggregate_init(failing_fold, qtable(_, V), V).
dfrl_aggregation:aggregate_step(failing_fold, _, _, _) :- fail.
dfrl_aggregation:aggregate_final(failing_fold, A, A).
% a method whose finished aggregate is one value short
dfrl_aggregation:aggregate_init(short_fold, qtable(_, V), V).
dfrl_aggregation:aggregate_step(short_fold, A, _, A).
dfrl_aggregation:aggregate_final(short_fold, [_|A], A).

wait_for(G) :- wait_for(G, 500).
wait_for(G, N) :- ( call(G) -> true ; N > 0 -> sleep(0.02), N1 is N-1, wait_for(G, N1) ; fail ).

log_events(File, Events) :-
    (   exists_file(File)
    ->  read_file_to_string(File, Text, []),
        split_string(Text, "\n", "", Lines0),
        exclude(==(""), Lines0, Lines),
        maplist([L, D]>>( open_string(L, In),
                          json_read_dict(In, D, [value_string_as(atom)]) ),
                Lines, Events)
    ;   Events = []
    ).

events(File, Type, Events) :-
    log_events(File, All),
    include([D]>>get_dict(event, D, Type), All, Events).

finished(File) :- events(File, finished, [_]).

nodes(N, Nodes) :-
    length(Nodes, N),
    maplist([X]>>node_start(localhost:0, X, [token(7), default(false)]), Nodes).

stop_of(Node, R, stop(localhost, P, R)) :- node_property(Node, address(_:P)).

launch(Console, Name, Stops, Method, Rounds, Log, Kind) :-
    dfrl_create(Console, Name, plan(Stops, Rounds, 0.0, Log, 30),
                [method(Method), tokens([7]), itinerary(Kind), skip_after(1)]),
    Stops = [stop(H, P, _)|_],
    with_node(Console, move_agent(Name, (H, P))).

tmp_log(Log) :-
    tmp_file(rounds, F),
    atom_concat(F, '.jsonl', Log).

cleanup_all(Log) :-
    memory_robots_stop,
    forall(local_node(N), catch(node_stop(N), _, true)),
    ( exists_file(Log) -> delete_file(Log) ; true ).

%   Seven robots with different tables (2 actions, 2 states).
robots(7, Robots) :-
    findall(R-[A,B,C,D],
            ( between(1, 7, I), format(atom(R), 'r~w', [I]),
              A is I * 0.1, B is 1.0 / I, C is I * I * 0.37, D is -0.3 * I ),
            Robots).

%   Start the robots and one node per robot plus the console, launch agent
%   Name over a binary tree of them and wait until it finished.
run_tree(Robots, Name, Method, Rounds, Log, Ids) :-
    memory_robots_start(Robots),
    length(Robots, N),
    N1 is N + 1,
    nodes(N1, [C|Ns]),
    pairs_keys(Robots, Ids),
    maplist(stop_of, Ns, Ids, Stops),
    launch(C, Name, Stops, Method, Rounds, Log, tree(2)),
    assertion(wait_for(finished(Log))).

chain_result(Method, Robots, Values) :-
    maplist([_-V, qtable([2,2], V)]>>true, Robots, Tables),
    aggregate_tables(Method, Tables, qtable(_, Values)).

:- begin_tests(dfrl_tree).

test(tree_shape) :-
    tree_children(0, 2, 7, [1,2]),
    tree_children(2, 2, 7, [5,6]),
    tree_children(3, 2, 7, []),
    tree_children(1, 3, 7, [4,5,6]),
    tree_subtree(1, 2, 7, [1,3,4]),
    tree_subtree(0, 3, 7, S), msort(S, [0,1,2,3,4,5,6]).

test(average_equals_the_chain_bit_for_bit, [cleanup(cleanup_all(Log))]) :-
    tmp_log(Log),
    robots(7, Robots),
    run_tree(Robots, ft, average, 2, Log, Ids),
    chain_result(average, Robots, Expected1),
    % round 2 averages seven copies of it (not exactly it again, in floats)
    maplist([R-_, R-Expected1]>>true, Robots, Robots2),
    chain_result(average, Robots2, Expected),
    % the control: the mean of the subtrees' means (r1; r2 r4 r5; r3 r6 r7) is another table
    Robots = [Q1-_, Q2-_, Q3-_, Q4-_, Q5-_, Q6-_, Q7-_],
    maplist([Ids0, M]>>( include([R-_]>>memberchk(R, Ids0), Robots, Sub),
                         chain_result(average, Sub, V), M = x-V ),
            [[Q1], [Q2,Q4,Q5], [Q3,Q6,Q7]], Means),
    chain_result(average, Means, OfMeans),
    assertion(OfMeans \== Expected1),
    forall(member(R, Ids), assertion(memory_robot_table(R, Expected))),
    forall(member(R, Ids), assertion(memory_robot_sets(R, 2))),
    events(Log, round, [R1, R2]),
    assertion(R1.visited == Ids), assertion(R2.visited == Ids),
    assertion(R1.skipped == []),
    assertion(R1.itinerary == tree), assertion(R1.fanout == 2),
    assertion(R1.hops =:= 6),               % one clone per stop but the root
    assertion(R1.bytes > 0).

test(order_kept_with_fanout_three, [cleanup(cleanup_all(Log))]) :-
    tmp_log(Log),
    robots(7, Robots),
    memory_robots_start(Robots),
    nodes(8, [C|Ns]),
    pairs_keys(Robots, Ids),
    maplist(stop_of, Ns, Ids, Stops),
    launch(C, fo, Stops, first_table, 1, Log, tree(3)),
    assertion(wait_for(finished(Log))),
    Robots = [_-First|_],
    forall(member(R, Ids), assertion(memory_robot_table(R, First))),
    events(Log, round, [R1]),
    assertion(R1.visited == Ids).

test(max_over_a_tree, [cleanup(cleanup_all(Log))]) :-
    tmp_log(Log),
    robots(7, Robots0),
    Robots0 = [_|Robots],                   % six robots: an incomplete last level
    run_tree(Robots, fx, max, 1, Log, Ids),
    chain_result(max, Robots, Expected),
    forall(member(R, Ids), assertion(memory_robot_table(R, Expected))).

test(failing_method_falls_back_within_the_tree_round,
     [setup(assertz(user:quiet)), cleanup((retractall(user:quiet), cleanup_all(Log)))]) :-
    tmp_log(Log),
    robots(7, Robots0),
    Robots0 = [_|Robots],
    run_tree(Robots, ft, failing_fold, 2, Log, Ids),
    events(Log, round, [R1, R2]),
    % round 1 ran again with average at once: every robot written, the failure logged
    assertion(R1.method == average),
    assertion(R1.failed_method == failing_fold),
    assertion(R1.error == 'aggregate_step(failing_fold) failed'),
    assertion(length(R1.visited, 6)),
    assertion(R2.method == average),
    assertion(\+ get_dict(error, R2, _)),
    events(Log, control, [F]),
    assertion(F.command == 'fallback(failing_fold,average)'),
    chain_result(average, Robots, Expected0),
    % round 2 averages equal tables: the same values again
    forall(member(R, Ids), assertion(memory_robot_table(R, Expected0))),
    forall(member(R, Ids), assertion(memory_robot_sets(R, 2))).

test(misshapen_final_falls_back_within_the_tree_round,
     [setup(assertz(user:quiet)), cleanup((retractall(user:quiet), cleanup_all(Log)))]) :-
    tmp_log(Log),
    robots(7, Robots0),
    Robots0 = [_|Robots],
    run_tree(Robots, fs, short_fold, 1, Log, Ids),
    events(Log, round, [R1]),
    % the root found the short aggregate before any write: done again with average
    assertion(R1.method == average),
    assertion(R1.failed_method == short_fold),
    assertion(sub_atom(R1.error, _, _, _, 'aggregate_size(4)')),
    assertion(length(R1.visited, 6)),
    assertion(R1.skipped == []),
    chain_result(average, Robots, Expected),
    forall(member(R, Ids), assertion(memory_robot_table(R, Expected))),
    forall(member(R, Ids), assertion(memory_robot_sets(R, 1))).

test(dead_stop_skipped_its_children_kept, [setup(assertz(user:quiet)),
                                           cleanup((retractall(user:quiet),
                                                    cleanup_all(Log)))]) :-
    tmp_log(Log),
    robots(7, Robots),
    memory_robots_start(Robots),
    nodes(8, [C|Ns]),
    pairs_keys(Robots, Ids),
    maplist(stop_of, Ns, Ids, Stops),
    nth0(1, Ns, Dead),                      % r2: position 1, the parent of r4 and r5
    node_stop(Dead),
    launch(C, fd, Stops, average, 1, Log, tree(2)),
    assertion(wait_for(finished(Log))),
    events(Log, round, [R1]),
    subtract(Ids, [r2], Alive),
    assertion(R1.visited == Alive),
    assertion(R1.skipped = [_{robot:r2, reason:_}]),
    R1.skipped = [Skip],
    assertion(sub_atom(Skip.reason, _, _, _, 'skipped after')),
    assertion(sub_atom(Skip.reason, _, _, _, 'a tree clone')),
    subtract(Robots, [r2-_], AliveRobots),
    chain_result(average, AliveRobots, Expected),
    forall(member(R, Alive), assertion(memory_robot_table(R, Expected))),
    assertion(memory_robot_sets(r2, 0)).

test(clone_lost_in_the_round_its_children_adopted,
     [cleanup(cleanup_all(Log))]) :-
    tmp_log(Log),
    robots(7, Robots),
    memory_robots_start(Robots),
    memory_robot_delay(r2, 2.5),            % the copy at r2 stays in its read
    nodes(8, [C|Ns]),
    pairs_keys(Robots, Ids),
    maplist(stop_of, Ns, Ids, Stops),
    launch(C, fl, Stops, average, 1, Log, tree(2)),
    nth0(1, Ns, R2Node),
    % the copy at r2 is lost (purged: its node no longer holds it) once r4 and r5 have theirs
    assertion(wait_for(( agents:agent_list(R2Node, [agent(Copy, _, _, _)]),
                         memory_robot_options(r5, get, _) ))),
    with_node(R2Node, purge_agent(Copy)),
    assertion(wait_for(finished(Log))),
    events(Log, round, [R1]),
    subtract(Ids, [r2], Alive),
    % r2's copy lost inside the round; r4 and r5, below it, adopted by the root
    assertion(R1.visited == Alive),
    assertion(R1.skipped = [_{robot:r2, reason:_}]),
    R1.skipped = [Skip],
    assertion(sub_atom(Skip.reason, _, _, _, 'its children were adopted')),
    subtract(Robots, [r2-_], AliveRobots),
    chain_result(average, AliveRobots, Expected),
    forall(member(R, Alive), assertion(memory_robot_table(R, Expected))).

test(bad_itinerary_refused, [cleanup(cleanup_all('/nonexistent.jsonl'))]) :-
    nodes(1, [C]),
    Plan = plan([stop(localhost, 1, r1)], 1, 0.0, 'x.jsonl', 30),
    catch(dfrl_create(C, b1, Plan, [itinerary(tree(1))]), E1, true),
    assertion(E1 = error(domain_error(fanout, 1), _)),
    catch(dfrl_create(C, b2, Plan, [itinerary(ring)]), E2, true),
    assertion(E2 = error(domain_error(itinerary, ring), _)).

:- end_tests(dfrl_tree).
