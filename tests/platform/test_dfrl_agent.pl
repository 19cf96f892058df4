/*  plunit tests of the dFRL itinerary agent on in-process nodes. The robots
    are played by a Prolog thread that serves the bridge's request queue the
    way the Python host does (pybridge/robot_bridge.pl protocol).
*/
:- use_module('../../platform_pl/tartarus').
:- use_module('../../platform_pl/agents/dfrl_agent').
:- use_module('../../pybridge/robot_bridge').
:- use_module(library(plunit)).

:- dynamic robot_table/2, sets/2, stop_flag/0, quiet/0.

% the skip test expects warnings about the unreachable stop: keep them quiet
:- multifile user:message_hook/3.
user:message_hook(_, warning, _) :- quiet.

host_start(Robots) :-
    retractall(robot_table(_, _)), retractall(sets(_, _)), retractall(stop_flag),
    forall(member(R-V, Robots),
           ( length(V, N), A is N // 2,
             bridge_register_robot(R, [algorithm(q), shape([A, 2])]),
             assertz(robot_table(R, V)), assertz(sets(R, 0)) )),
    thread_create(host_loop, _, [alias(test_host)]).

host_stop :-
    assertz(stop_flag),
    thread_join(test_host, _),
    forall(robot_table(R, _), bridge_unregister_robot(R)).

host_loop :-
    (   stop_flag
    ->  true
    ;   (   bridge_next_request(request(Id, Op), 0.05)
        ->  catch(serve(Op, Reply), E, (E = error(F, _) -> Reply = error(F) ; Reply = error(E))),
            bridge_reply(Id, Reply)
        ;   true
        ),
        host_loop
    ).

serve(get_qtable(R), table(S, D)) :-
    robot_table(R, V), shape(V, S), robot_bridge:encode_values(V, D).
serve(get_qtable_and_visits(R), tables(table(S, D), table(S, W))) :-
    robot_table(R, V), shape(V, S), robot_bridge:encode_values(V, D),
    maplist([_, 1.0]>>true, V, Ones), robot_bridge:encode_values(Ones, W).
serve(set_qtable(R, _S, D), ok) :-
    robot_bridge:decode_values(D, V),
    retract(robot_table(R, _)), assertz(robot_table(R, V)),
    retract(sets(R, N)), N1 is N + 1, assertz(sets(R, N1)).

shape(V, [A, 2]) :- length(V, N), A is N // 2.

wait_for(G) :- wait_for(G, 250).
wait_for(G, N) :- ( call(G) -> true ; N > 0 -> sleep(0.02), N1 is N-1, wait_for(G, N1) ; fail ).

log_terms(File, Terms) :-
    (   exists_file(File)
    ->  setup_call_cleanup(open(File, read, In), read_all(In, Terms), close(In))
    ;   Terms = []
    ).
read_all(In, Ts) :- read_term(In, T, []), ( T == end_of_file -> Ts = [] ; Ts = [T|R], read_all(In, R) ).

finished(File) :- log_terms(File, Ts), memberchk(finished(_), Ts).

nodes(N, Nodes) :-
    length(Nodes, N),
    maplist([X]>>node_start(localhost:0, X, [token(7), default(false)]), Nodes).

stop_of(Node, R, stop(localhost, P, R)) :- node_property(Node, address(_:P)).

launch(Console, Name, Stops, Method, Rounds, Log) :-
    dfrl_create(Console, Name, plan(Stops, Rounds, 0.0, Log, 30), [method(Method), tokens([7])]),
    Stops = [stop(H, P, _)|_],
    with_node(Console, move_agent(Name, (H, P))).

:- begin_tests(dfrl_agent, [setup(true)]).

test(average_two_rounds, [cleanup((host_stop, forall(member(N, [C,A,B,D]), node_stop(N)), delete_file(Log)))]) :-
    tmp_file(rounds, Log),
    host_start([r1-[1.0,2.0,0.0,0.0], r2-[3.0,4.0,0.0,0.0], r3-[5.0,12.0,3.0,0.0]]),
    nodes(4, [C,A,B,D]),
    maplist(stop_of, [A,B,D], [r1,r2,r3], Stops),
    launch(C, fa, Stops, average, 2, Log),
    assertion(wait_for(finished(Log))),
    forall(member(R, [r1,r2,r3]), assertion(robot_table(R, [3.0,6.0,1.0,0.0]))),
    forall(member(R, [r1,r2,r3]), assertion(sets(R, 2))),
    log_terms(Log, [round(1, S1, E1, Hops, Bytes, average, Visited), round(2, _, _, _, _, _, _), finished(2)]),
    assertion(E1 >= S1),
    assertion(Hops =:= 4),
    assertion(Bytes > 0),
    assertion(Visited == [r1, r2, r3]).

test(max_and_visit_average, [cleanup((host_stop, forall(member(N, [C,A,B]), node_stop(N)), delete_file(Log)))]) :-
    tmp_file(rounds, Log),
    host_start([r1-[1.0,7.0], r2-[3.0,4.0]]),
    nodes(3, [C,A,B]),
    maplist(stop_of, [A,B], [r1,r2], Stops),
    launch(C, fm, Stops, max, 1, Log),
    assertion(wait_for(finished(Log))),
    assertion(robot_table(r1, [3.0,7.0])),
    assertion(robot_table(r2, [3.0,7.0])).

test(join_and_injected_method, [cleanup((host_stop, forall(member(N, [C,A,B,D]), node_stop(N)), delete_file(Log)))]) :-
    tmp_file(rounds, Log),
    host_start([r1-[1.0,9.0], r2-[3.0,5.0], r3-[2.0,7.0]]),
    nodes(4, [C,A,B,D]),
    maplist(stop_of, [A,B,D], [r1,r2,r3], [S1,S2,S3]),
    % a method injected into the nodes as a program text, and a robot joining
    module_property(dfrl_agent, file(AgentFile)),
    file_directory_name(AgentFile, Dir),
    directory_file_path(Dir, 'examples/median_method.pl', Median),
    node_property(A, address(AA)),
    with_node(C, load_program_at(AA, Median, [tokens([7])])),
    agent_post(AA, platform, dfrl_control, x, [method(median)]),
    agent_post(AA, platform, dfrl_control, x, [join(S3)]),
    assertion(wait_for(dfrl_agent:pending(join(_)))),
    launch(C, fj, [S1,S2], average, 1, Log),
    assertion(wait_for(finished(Log))),
    log_terms(Log, [round(1, _, _, _, _, Method, Visited)|_]),
    assertion(Method == median),
    assertion(Visited == [r1, r2, r3]),
    assertion(robot_table(r1, [2.0,7.0])).

test(unreachable_stop_is_skipped, [setup(assertz(quiet)), cleanup((retractall(quiet), host_stop, forall(member(N, [C,A,B]), node_stop(N)), delete_file(Log)))]) :-
    tmp_file(rounds, Log),
    host_start([r1-[1.0,1.0], r2-[3.0,3.0], r3-[9.0,9.0]]),
    nodes(4, [C,A,Gone,B]),
    maplist(stop_of, [A,Gone,B], [r1,r3,r2], Stops),
    node_stop(Gone),
    launch(C, fs, Stops, average, 1, Log),
    assertion(wait_for(finished(Log))),
    log_terms(Log, [round(1, _, _, _, _, average, Visited)|_]),
    assertion(Visited == [r1, r2]),
    assertion(robot_table(r1, [2.0,2.0])),
    assertion(robot_table(r3, [9.0,9.0])).

:- end_tests(dfrl_agent).
