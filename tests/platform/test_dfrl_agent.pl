/*  plunit tests of the dFRL itinerary agent on in-process nodes. The robots
    are in-memory tables behind the resource hook (memory_robots.pl); the
    round log is read back as JSON lines.
*/
:- use_module('../../platform_pl/tartarus').
:- use_module('../../platform_pl/dfrl_agent/dfrl_agent').
:- use_module(memory_robots).
:- use_module('../../platform_pl/agents', [agent_execute/4, agent_exists/2]).
:- use_module('../../platform_pl/node', [local_node/1]).
:- use_module(library(plunit)).
:- use_module(library(http/json)).

:- dynamic quiet/0.

% the skip tests expect warnings about the unreachable stop and the unknown
% robot: keep them quiet (asserted first, before plunit's own hook)
:- multifile user:message_hook/3.
:- dynamic user:message_hook/3.
:- asserta((user:message_hook(_, warning, _) :- quiet)).
:- asserta((user:message_hook(_, error, _) :- quiet)).

% methods that go wrong at run time: a step that fails, a final that throws
:- multifile dfrl_aggregation:aggregate_init/3, dfrl_aggregation:aggregate_step/4,
             dfrl_aggregation:aggregate_final/3.
dfrl_aggregation:aggregate_init(failing_step, qtable(_, V), V).
dfrl_aggregation:aggregate_step(failing_step, _, _, _) :- fail.
dfrl_aggregation:aggregate_final(failing_step, A, A).
dfrl_aggregation:aggregate_init(throwing_final, qtable(_, V), V).
dfrl_aggregation:aggregate_step(throwing_final, A, _, A).
dfrl_aggregation:aggregate_final(throwing_final, _, _) :-
    type_error(integer, not_a_number).
% methods whose finished aggregate is no table of the carried shape
dfrl_aggregation:aggregate_init(short_final, qtable(_, V), V).
dfrl_aggregation:aggregate_step(short_final, A, _, A).
dfrl_aggregation:aggregate_final(short_final, _, [0.0]).
dfrl_aggregation:aggregate_init(wrapped_final, qtable(_, V), V).
dfrl_aggregation:aggregate_step(wrapped_final, A, _, A).
dfrl_aggregation:aggregate_final(wrapped_final, A, wrapped(A)).

wait_for(G) :- wait_for(G, 250).
wait_for(G, N) :- ( call(G) -> true ; N > 0 -> sleep(0.02), N1 is N-1, wait_for(G, N1) ; fail ).

%   The events of a round log, one dict per JSON line (strings as atoms).
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
    nodes(N, [], Nodes).

nodes(N, Options, Nodes) :-
    length(Nodes, N),
    maplist([X]>>node_start(localhost:0, X, [token(7), default(false)|Options]), Nodes).

stop_of(Node, R, stop(localhost, P, R)) :- node_property(Node, address(_:P)).

launch(Console, Name, Stops, Method, Rounds, Log) :-
    dfrl_create(Console, Name, plan(Stops, Rounds, 0.0, Log, 30), [method(Method), tokens([7])]),
    Stops = [stop(H, P, _)|_],
    with_node(Console, move_agent(Name, (H, P))).

cleanup_all(Log) :-
    findall(N, local_node(N), Nodes),
    cleanup(Nodes, Log).

%   A fresh round-log name: the agent appends only to .log/.jsonl files.
tmp_log(Log) :-
    tmp_file(rounds, F),
    atom_concat(F, '.jsonl', Log).

cleanup(Nodes, Log) :-
    memory_robots_stop,
    forall(member(N, Nodes), catch(node_stop(N), _, true)),
    ( exists_file(Log) -> delete_file(Log) ; true ).

:- begin_tests(dfrl_agent).

test(average_two_rounds, [cleanup(cleanup([C,A,B,D], Log))]) :-
    tmp_log(Log),
    memory_robots_start([r1-[1.0,2.0,0.0,0.0], r2-[3.0,4.0,0.0,0.0], r3-[5.0,12.0,3.0,0.0]]),
    nodes(4, [C,A,B,D]),
    maplist(stop_of, [A,B,D], [r1,r2,r3], Stops),
    launch(C, fa, Stops, average, 2, Log),
    assertion(wait_for(finished(Log))),
    forall(member(R, [r1,r2,r3]), assertion(memory_robot_table(R, [3.0,6.0,1.0,0.0]))),
    forall(member(R, [r1,r2,r3]), assertion(memory_robot_sets(R, 2))),
    log_events(Log, [R1, R2, F]),
    assertion(R1.event == round), assertion(R1.agent == fa), assertion(R1.round == 1),
    assertion(R1.end >= R1.start), assertion(R1.start > 0),
    assertion(R1.hops =:= 4),
    assertion(R1.bytes > 0),
    assertion(R1.method == average),
    assertion(R1.visited == [r1, r2, r3]),
    assertion(R1.skipped == []),
    assertion(R2.round == 2),
    assertion(F = _{event:finished, agent:fa, round:2}).

test(max_and_visit_average, [cleanup(cleanup([C,A,B], Log))]) :-
    tmp_log(Log),
    memory_robots_start([r1-[1.0,7.0], r2-[3.0,4.0]]),
    nodes(3, [C,A,B]),
    maplist(stop_of, [A,B], [r1,r2], Stops),
    launch(C, fm, Stops, max, 1, Log),
    assertion(wait_for(finished(Log))),
    assertion(memory_robot_table(r1, [3.0,7.0])),
    assertion(memory_robot_table(r2, [3.0,7.0])).

test(visit_average_uses_visits, [cleanup(cleanup([C,A,B], Log))]) :-
    tmp_log(Log),
    memory_robots_start([r1-[1.0,7.0], r2-[3.0,5.0]]),
    nodes(3, [C,A,B]),
    maplist(stop_of, [A,B], [r1,r2], Stops),
    launch(C, fv, Stops, visit_average, 1, Log),
    assertion(wait_for(finished(Log))),
    assertion(memory_robot_table(r1, [2.0,6.0])),
    events(Log, round, [R]),
    assertion(R.method == visit_average).

test(join_and_injected_method, [cleanup(cleanup([C,A,B,D], Log))]) :-
    tmp_log(Log),
    memory_robots_start([r1-[1.0,9.0], r2-[3.0,5.0], r3-[2.0,7.0]]),
    nodes(4, [C,A,B,D]),
    maplist(stop_of, [A,B,D], [r1,r2,r3], [S1,S2,S3]),
    % a method injected into the nodes as a program text, and a robot joining
    module_property(dfrl_agent, file(AgentFile)),
    file_directory_name(AgentFile, Dir),
    directory_file_path(Dir, 'examples/median_method.pl', Median),
    node_property(A, address(AA)),
    with_node(C, load_program_at(AA, Median, [tokens([7])])),
    agent_post(AA, platform, dfrl_control, x, [fj, method(median)]),
    assertion(wait_for(dfrl_pending(A, fj, method(_)))),   % posts are asynchronous
    agent_post(AA, platform, dfrl_control, x, [fj, join(S3)]),
    agent_post(AA, platform, dfrl_control, x, [other, stop]),
    assertion(wait_for(dfrl_pending(A, fj, join(_)))),
    assertion(wait_for(dfrl_pending(A, other, stop))),
    launch(C, fj, [S1,S2], average, 1, Log),
    assertion(wait_for(finished(Log))),
    events(Log, control, Controls),
    format(atom(Join), '~q', [join(S3)]),
    assertion(Controls = [ _{event:control, agent:fj, round:1,
                              command:'method(median)', status:applied, time:_},
                            _{event:control, agent:fj, round:1,
                              command:Join, status:applied, time:_} ]),
    events(Log, round, [R]),
    assertion(R.method == median),
    assertion(R.visited == [r1, r2, r3]),
    assertion(memory_robot_table(r1, [2.0,7.0])),
    % the command for another agent is still queued, untouched
    assertion(dfrl_pending(A, other, stop)),
    retractall(dfrl_commands:pending(_, other, _)).

test(unknown_method_ignored_and_stop, [cleanup(cleanup([C,A,B], Log))]) :-
    tmp_log(Log),
    memory_robots_start([r1-[1.0,1.0], r2-[3.0,3.0]]),
    nodes(3, [C,A,B]),
    maplist(stop_of, [A,B], [r1,r2], Stops),
    node_property(A, address(AA)),
    agent_post(AA, platform, dfrl_control, x, [fu, method(no_such_method)]),
    assertion(wait_for(dfrl_pending(A, fu, method(_)))),
    agent_post(AA, platform, dfrl_control, x, [fu, stop]),
    assertion(wait_for(dfrl_pending(A, fu, stop))),
    launch(C, fu, Stops, max, 5, Log),
    assertion(wait_for(finished(Log))),
    log_events(Log, [Ignored, Stop, Round, Finished]),
    assertion(Ignored.status == ignored),
    assertion(Ignored.command == 'method(no_such_method)'),
    assertion(sub_atom(Ignored.reason, _, _, _, 'unknown method')),
    assertion(Stop.command == stop), assertion(Stop.status == applied),
    assertion(Round.method == max),
    assertion(Finished.round == 1).

test(failing_method_falls_back_within_its_round,
     [setup(assertz(user:quiet)),
      cleanup((retractall(user:quiet), cleanup([C,A,B,D], Log)))]) :-
    tmp_log(Log),
    memory_robots_start([r1-[1.0,2.0], r2-[3.0,4.0], r3-[5.0,6.0]]),
    nodes(4, [C,A,B,D]),
    maplist(stop_of, [A,B,D], [r1,r2,r3], Stops),
    launch(C, ff, Stops, failing_step, 2, Log),
    assertion(wait_for(finished(Log))),
    events(Log, round, [R1, R2]),
    % r2's step failed; no method had worked yet, so the round started again from r1
    % with average and finished: every robot written, the failure on record
    assertion(R1.method == average),
    assertion(R1.failed_method == failing_step),
    assertion(R1.error == 'aggregate_step(failing_step) failed'),
    assertion(R1.visited == [r1, r2, r3]),
    assertion(R1.skipped == []),
    events(Log, control, [F]),
    assertion(F.command == 'fallback(failing_step,average)'),
    assertion(F.round == 1), assertion(F.status == applied),
    assertion(R2.method == average),
    assertion(\+ get_dict(error, R2, _)),
    assertion(\+ get_dict(failed_method, R2, _)),
    forall(member(R, [r1,r2,r3]), assertion(memory_robot_sets(R, 2))),
    forall(member(R, [r1,r2,r3]), assertion(memory_robot_table(R, [3.0,4.0]))).

test(failing_method_falls_back_to_the_last_that_worked,
     [setup(assertz(user:quiet)),
      cleanup((retractall(user:quiet), cleanup([C,A,B], Log)))]) :-
    tmp_log(Log),
    memory_robots_start([r1-[1.0,5.0], r2-[3.0,4.0]]),
    nodes(3, [C,A,B]),
    maplist(stop_of, [A,B], [r1,r2], Stops),
    node_property(A, address(AA)),
    % rounds 1 and 3 with max; the method applied at round 2 fails there, and round 2
    % is done with max
    dfrl_create(C, fb, plan(Stops, 3, 0.5, Log, 30), [method(max), tokens([7])]),
    Stops = [stop(H, P, _)|_],
    with_node(C, move_agent(fb, (H, P))),
    assertion(wait_for(events(Log, round, [_]), 200)),
    agent_post(AA, platform, dfrl_control, x, [fb, method(failing_step)]),
    assertion(wait_for(finished(Log), 400)),
    events(Log, round, [R1, R2, R3]),
    assertion(R1.method == max), assertion(\+ get_dict(error, R1, _)),
    assertion(R2.method == max), assertion(R2.failed_method == failing_step),
    assertion(get_dict(error, R2, _)),
    assertion(R2.visited == [r1, r2]),
    assertion(R3.method == max), assertion(\+ get_dict(error, R3, _)),
    events(Log, control, Controls),
    assertion(( member(M, Controls), get_dict(command, M, 'method(failing_step)') )),
    assertion(( member(F, Controls), get_dict(command, F, 'fallback(failing_step,max)'),
                get_dict(round, F, 2), get_dict(status, F, applied) )),
    forall(member(R, [r1,r2]), assertion(memory_robot_sets(R, 3))),
    assertion(memory_robot_table(r1, [3.0,5.0])).

test(throwing_final_falls_back_within_its_round,
     [setup(assertz(user:quiet)),
      cleanup((retractall(user:quiet), cleanup([C,A,B], Log)))]) :-
    tmp_log(Log),
    memory_robots_start([r1-[1.0,2.0], r2-[3.0,4.0]]),
    nodes(3, [C,A,B]),
    maplist(stop_of, [A,B], [r1,r2], Stops),
    launch(C, ft, Stops, throwing_final, 1, Log),
    assertion(wait_for(finished(Log))),
    events(Log, round, [R]),
    assertion(sub_atom(R.error, 0, _, _, 'aggregate_final(throwing_final) raised: ')),
    assertion(sub_atom(R.error, _, _, _, not_a_number)),
    assertion(R.failed_method == throwing_final),
    assertion(R.method == average),
    assertion(R.visited == [r1, r2]),
    % the round started again at r1: four hops, not two
    assertion(R.hops >= 4),
    forall(member(Rb, [r1,r2]), assertion(memory_robot_sets(Rb, 1))),
    forall(member(Rb, [r1,r2]), assertion(memory_robot_table(Rb, [2.0,3.0]))).

%   A finished aggregate of the wrong length, or no vector at all, is the
%   method's failure, found before anything is written: the round is done
%   again with the fallback, and the error does not carry the values.
test(misshapen_final_falls_back_within_its_round,
     [setup(assertz(user:quiet)),
      cleanup((retractall(user:quiet), cleanup([C,A,B], Log))),
      forall(member(Method-Says, [short_final-'aggregate_size(400)',
                                  wrapped_final-'float_vector']))]) :-
    tmp_log(Log),
    numlist(1, 400, Ns),
    maplist([N, X]>>(X is float(N)), Ns, V1),
    maplist([N, X]>>(X is float(N + 2)), Ns, V2),
    maplist([N, X]>>(X is float(N + 1)), Ns, Mean),
    memory_robots_start([r1-V1, r2-V2]),
    nodes(3, [C,A,B]),
    maplist(stop_of, [A,B], [r1,r2], Stops),
    launch(C, fm, Stops, Method, 1, Log),
    assertion(wait_for(finished(Log))),
    events(Log, round, [R]),
    assertion(sub_atom(R.error, 0, _, _, 'aggregate_final(')),
    assertion(sub_atom(R.error, _, _, _, Says)),
    get_dict(error, R, Error), atom_length(Error, L),
    assertion(L < 400),
    assertion(R.failed_method == Method),
    assertion(R.method == average),
    assertion(R.skipped == []),
    forall(member(Rb, [r1,r2]), assertion(memory_robot_sets(Rb, 1))),
    forall(member(Rb, [r1,r2]), assertion(memory_robot_table(Rb, Mean))).

test(unreachable_stop_is_skipped, [setup(assertz(user:quiet)),
                                   cleanup((retractall(user:quiet), cleanup([C,A,B], Log)))]) :-
    tmp_log(Log),
    memory_robots_start([r1-[1.0,1.0], r2-[3.0,3.0], r3-[9.0,9.0]]),
    nodes(4, [C,A,Gone,B]),
    maplist(stop_of, [A,Gone,B], [r1,r3,r2], Stops),
    node_stop(Gone),
    launch(C, fs, Stops, average, 1, Log),
    assertion(wait_for(finished(Log))),
    events(Log, round, [R]),
    assertion(R.visited == [r1, r2]),
    R.skipped = [Skip],
    assertion(Skip.robot == r3),
    assertion(sub_atom(Skip.reason, _, _, _, 'cannot connect')),
    assertion(R.retries == 2),                      % two retries, then skipped
    assertion(R.epoch == 1),
    assertion(memory_robot_table(r1, [2.0,2.0])),
    assertion(memory_robot_table(r3, [9.0,9.0])).

test(unknown_robot_is_skipped, [setup(assertz(user:quiet)),
                                cleanup((retractall(user:quiet), cleanup([C,A,B], Log)))]) :-
    tmp_log(Log),
    memory_robots_start([r1-[1.0,1.0]]),
    nodes(3, [C,A,B]),
    maplist(stop_of, [A,B], [r1,nobody], Stops),
    launch(C, fn, Stops, average, 1, Log),
    assertion(wait_for(finished(Log))),
    events(Log, round, [R]),
    assertion(R.visited == [r1]),
    R.skipped = [Skip],
    assertion(Skip.robot == nobody),
    assertion(sub_atom(Skip.reason, _, _, _, 'does not exist')),
    assertion(memory_robot_table(r1, [1.0,1.0])).

test(table_requests_say_where_they_come_from,
     [cleanup(cleanup([C,A,B], Log))]) :-
    tmp_log(Log),
    memory_robots_start([r1-[1.0,1.0], r2-[3.0,3.0]]),
    nodes(3, [C,A,B]),
    maplist(stop_of, [A,B], [r1,r2], Stops),
    launch(C, fo, Stops, average, 2, Log),
    assertion(wait_for(finished(Log))),
    once(memory_robot_options(r2, get, Get)),
    % a read also asks for packed values (a host that has none gives lists)
    assertion(subsumes_term([values(packed), timeout(_), round(2), agent(fo), epoch(1)], Get)),
    once(memory_robot_options(r1, set, Set)),
    assertion(subsumes_term([timeout(_), round(2), agent(fo), epoch(1)], Set)).

%   The first stop is down at launch and for the first round: the agent
%   starts its rounds at the next stop it reaches, tries the first stop
%   again every round, and visits it again once it is back.
test(unreachable_first_stop_rehomes_and_comes_back,
     [setup(assertz(user:quiet)),
      cleanup((retractall(user:quiet), cleanup_all(Log)))]) :-
    tmp_log(Log),
    memory_robots_start([r1-[1.0,1.0], r2-[3.0,3.0], r3-[5.0,5.0]]),
    nodes(4, [C,A,B,D]),
    maplist(stop_of, [A,B,D], [r1,r2,r3], Stops),
    node_property(A, address(_:PortA)),
    node_stop(A),
    dfrl_create(C, fh, plan(Stops, 3, 0.4, Log, 30),
                [tokens([7]), retries(1), backoff(0.05)]),
    node_property(C, link(Link)),
    with_node(C, agent_execute(C, fh, Link, launch)),
    assertion(wait_for(events(Log, round, [_]))),
    events(Log, round, [R1]),
    assertion(R1.visited == [r2, r3]),
    assertion(R1.skipped = [_{robot:r1, reason:_}]),
    assertion(R1.retries >= 1),
    % the first stop comes back, on its port, during the rest
    node_start(localhost:PortA, _, [token(7), default(false)]),
    assertion(wait_for(finished(Log), 500)),
    events(Log, round, Rounds),
    assertion(length(Rounds, 3)),
    last(Rounds, R3),
    assertion(R3.visited == [r1, r2, r3]),
    assertion(R3.skipped == []),
    assertion(memory_robot_table(r1, [3.0,3.0])),
    events(Log, aborted, Aborted),
    assertion(Aborted == []).

%   The agent dwells on a slow robot longer than its holder's lease: the
%   holder's probe finds it there and renews; nothing is resurrected.
test(lease_renewed_while_agent_works, [cleanup(cleanup([C,A,B], Log))]) :-
    tmp_log(Log),
    memory_robots_start([r1-[1.0,1.0], r2-[3.0,3.0]]),
    memory_robot_delay(r2, 1.0),
    nodes(3, [lease_s(0.2)], [C,A,B]),
    maplist(stop_of, [A,B], [r1,r2], Stops),
    launch(C, fl, Stops, average, 1, Log),
    assertion(wait_for(finished(Log), 400)),
    events(Log, resurrected, Res),
    assertion(Res == []),
    events(Log, round, [R]),
    assertion(R.visited == [r1, r2]),
    assertion(R.epoch == 1).

%   The node the agent is on dies mid-round: the stop it came from
%   resurrects it (epoch 2), it skips the dead stop and finishes its
%   rounds; later rounds skip the dead stop too.
test(agent_resurrected_when_its_node_dies,
     [setup(assertz(user:quiet)),
      cleanup((retractall(user:quiet), cleanup([C,A,D], Log)))]) :-
    tmp_log(Log),
    memory_robots_start([r1-[1.0,1.0], r2-[3.0,3.0], r3-[5.0,5.0]]),
    memory_robot_delay(r2, 1.0),
    nodes(4, [lease_s(0.3), connect_timeout(0.5), reply_timeout(1)], [C,A,B,D]),
    maplist(stop_of, [A,B,D], [r1,r2,r3], Stops),
    node_property(A, address(AAddr)),
    node_property(B, address(BAddr)),
    launch(C, fr, Stops, average, 2, Log),
    assertion(wait_for(agent_exists(B, fr), 200)),
    % A's checkpoint keeps the round state once: in its resume point
    assertion(( dfrl_lease:ckpt(A, fr, _, _, _, _, agent(_, _, _, _, _, _, Cls, _),
                                resume(S0, _, _), _),
                memberchk((dfrl_state(fr, in_resume) :- true), Cls),
                is_dict(S0) )),
    sleep(0.2),
    node_stop(B),
    assertion(wait_for(finished(Log), 500)),
    events(Log, resurrected, Resurrections),      % said in full if not one
    assertion(Resurrections = [_]),
    Resurrections = [Res],
    assertion(Res.round == 1),
    assertion(Res.epoch == 2),
    format(atom(AText), '~w', [AAddr]),
    format(atom(BText), '~w', [BAddr]),
    assertion(Res.from == AText),
    assertion(Res.dead == BText),
    events(Log, round, Rounds),
    assertion(Rounds = [_, _]),
    Rounds = [R1, R2],
    assertion(R1.visited == [r1, r3]),
    assertion(R1.skipped = [_{robot:r2, reason:_}]),
    R1.skipped = [Lost],
    assertion(sub_atom(Lost.reason, _, _, _, 'lost with its node')),
    assertion(R1.epoch == 2),
    assertion(R2.visited == [r1, r3]),
    assertion(R2.skipped = [_{robot:r2, reason:_}]),
    assertion(memory_robot_table(r1, [3.0,3.0])),
    assertion(memory_robot_table(r3, [3.0,3.0])),
    events(Log, finished, [_]),
    assertion(\+ dfrl_lease:lease_checkpoint(_, fr, _, _)).

:- end_tests(dfrl_agent).

:- begin_tests(round_log_path).

test(only_round_logs_in_existing_directories) :-
    tmp_log(Ok),
    assertion(dfrl_agent:log_path_ok(Ok)),
    tmp_file(rounds, NoExt),
    assertion(\+ dfrl_agent:log_path_ok(NoExt)),
    assertion(\+ dfrl_agent:log_path_ok('/nonexistent_dir_dfrl/rounds.log')),
    expand_file_name('~/.bashrc', [Rc]),
    assertion(\+ dfrl_agent:log_path_ok(Rc)).

:- end_tests(round_log_path).

/*  Parameter vectors (issue 19): FedAvg by hand, the methods refused for
    parameters, and an agent that carries params between robots whose
    parameters are held here (function learners behind the resource hook,
    beside memory_robots.pl's tables).
*/

:- dynamic mparams/4.                   % Robot, Layout, Samples, Values
:- multifile robot_resources:robot/2, robot_resources:params_get/3,
             robot_resources:params_set/3.

robot_resources:robot(R, [algo(test), learner(function), layout(L)]) :-
    mparams(R, L, _, _).
robot_resources:params_get(R, params(L, W, V), _) :-
    mparams(R, L, W, V).
robot_resources:params_set(R, params(L, V), _) :-
    with_mutex(mparams, ( retract(mparams(R, L, W, _)),
                          assertz(mparams(R, L, W, V)) )).

params_start(Robots) :-
    retractall(mparams(_, _, _, _)),
    forall(member(R-L-W-V, Robots), assertz(mparams(R, L, W, V))).

params_cleanup(Nodes, Log) :-
    retractall(mparams(_, _, _, _)),
    cleanup(Nodes, Log).

:- begin_tests(dfrl_params).

%   sum(w_i x_i) / sum(w_i): (1*[1,2] + 3*[3,6] + 0*[9,9]) / 4 = [2.5, 5.0]
test(fedavg_weighted_by_samples) :-
    L = [w-[2]],
    aggregate_tables(average, [params(L, 1, [1.0,2.0]), params(L, 3, [3.0,6.0]),
                               params(L, 0, [9.0,9.0])], T),
    assertion(T == params(L, [2.5,5.0])).

%   a learner without samples weighs nothing, wherever it comes; the
%   order of the robots changes no value here
test(fedavg_zero_weight_first) :-
    L = [w-[1,3], b-[1]],
    aggregate_tables(average, [params(L, 0, [7.0,7.0,7.0,7.0]),
                               params(L, 2, [1.0,2.0,3.0,4.0]),
                               params(L, 2, [3.0,4.0,5.0,-4.0])], T),
    assertion(T == params(L, [2.0,3.0,4.0,0.0])).

%   no learner has learnt yet: the plain mean
test(fedavg_all_zero_is_plain_mean) :-
    L = [w-[2]],
    aggregate_tables(average, [params(L, 0, [1.0,2.0]), params(L, 0, [3.0,8.0])], T),
    assertion(T == params(L, [2.0,5.0])).

%   tables keep the plain element-wise mean
test(average_of_tables_unchanged) :-
    aggregate_tables(average, [qtable([1,2], [1.0,2.0]), qtable([1,2], [3.0,8.0])], T),
    assertion(T == qtable([1,2], [2.0,5.0])).

test(params_of_another_layout_do_not_fit,
     [throws(error(domain_error(param_layout([w-[2]]), [w-[3]]), _))]) :-
    dfrl_aggregation:item_shape(params([w-[2]], 1, [1.0,2.0]), S0),
    dfrl_aggregation:aggregate_fold(average, none, S0, params([w-[2]], 1, [1.0,2.0]), Acc),
    dfrl_aggregation:item_shape(params([w-[3]], 1, [1.0,2.0,3.0]), S1),
    dfrl_aggregation:aggregate_fits(Acc, S1).

test(which_methods_apply) :-
    assertion(dfrl_aggregation:method_applies_to(average, params)),
    assertion(dfrl_aggregation:method_applies_to(average, tables)),
    assertion(\+ dfrl_aggregation:method_applies_to(max, params)),
    assertion(\+ dfrl_aggregation:method_applies_to(visit_average, params)),
    assertion(dfrl_aggregation:method_applies_to(max, tables)),
    assertion(dfrl_aggregation:method_applies_to(failing_step, tables)).

test(max_refused_for_params_at_create) :-
    catch(dfrl_create(nowhere, fx, plan([stop(localhost, 1, r1)], 1, 0.0, 'x.jsonl', 5),
                      [method(max), carries(params)]),
          E, true),
    assertion(E = error(domain_error(params_method, max), context(_, _))),
    E = error(_, context(_, Msg)),
    assertion(sub_string(Msg, _, _, _, "aggregation method max does not apply to parameter vectors")),
    assertion(sub_string(Msg, _, _, _, "function learners")),
    assertion(sub_string(Msg, _, _, _, "methods that do: average")).

test(visit_average_refused_for_params,
     [throws(error(domain_error(params_method, visit_average), _))]) :-
    dfrl_aggregation:check_method_applies(visit_average, params).

test(params_round_every_robot_holds_the_fedavg,
     [cleanup(params_cleanup([C,A,B,D], Log))]) :-
    tmp_log(Log),
    L = [w-[2]],
    params_start([r1-L-1-[1.0,2.0], r2-L-3-[3.0,6.0], r3-L-0-[9.0,9.0]]),
    nodes(4, [C,A,B,D]),
    maplist(stop_of, [A,B,D], [r1,r2,r3], Stops),
    dfrl_create(C, fp, plan(Stops, 2, 0.0, Log, 30),
                [method(average), carries(params), tokens([7])]),
    Stops = [stop(H, P, _)|_],
    with_node(C, move_agent(fp, (H, P))),
    assertion(wait_for(finished(Log))),
    forall(member(R, [r1,r2,r3]), assertion(mparams(R, L, _, [2.5,5.0]))),
    events(Log, round, [R1, R2]),
    assertion(R1.visited == [r1, r2, r3]),
    assertion(R1.skipped == []),
    assertion(R1.method == average),
    assertion(\+ get_dict(error, R1, _)),
    assertion(R2.visited == [r1, r2, r3]).

test(params_robot_of_another_layout_is_skipped,
     [setup(assertz(user:quiet)),
      cleanup((retractall(user:quiet), params_cleanup([C,A,B], Log)))]) :-
    tmp_log(Log),
    params_start([r1-[w-[2]]-1-[1.0,2.0], r2-[w-[3]]-1-[1.0,2.0,3.0]]),
    nodes(3, [C,A,B]),
    maplist(stop_of, [A,B], [r1,r2], Stops),
    dfrl_create(C, fk, plan(Stops, 1, 0.0, Log, 30), [carries(params), tokens([7])]),
    Stops = [stop(H, P, _)|_],
    with_node(C, move_agent(fk, (H, P))),
    assertion(wait_for(finished(Log))),
    events(Log, round, [R]),
    assertion(R.visited == [r1]),
    R.skipped = [Skip],
    assertion(Skip.robot == r2),
    assertion(sub_atom(Skip.reason, _, _, _, param_layout)),
    assertion(mparams(r2, _, _, [1.0,2.0,3.0])).

test(max_command_ignored_for_params,
     [cleanup(params_cleanup([C,A,B], Log))]) :-
    tmp_log(Log),
    L = [w-[1]],
    params_start([r1-L-1-[1.0], r2-L-1-[3.0]]),
    nodes(3, [C,A,B]),
    maplist(stop_of, [A,B], [r1,r2], Stops),
    node_property(A, address(AA)),
    agent_post(AA, platform, dfrl_control, x, [fq, method(max)]),
    assertion(wait_for(dfrl_pending(A, fq, method(_)))),
    dfrl_create(C, fq, plan(Stops, 1, 0.0, Log, 30), [carries(params), tokens([7])]),
    Stops = [stop(H, P, _)|_],
    with_node(C, move_agent(fq, (H, P))),
    assertion(wait_for(finished(Log))),
    events(Log, control, [Ctl]),
    assertion(Ctl.status == ignored),
    assertion(sub_atom(Ctl.reason, _, _, _, 'does not apply to params')),
    events(Log, round, [R]),
    assertion(R.method == average),
    assertion(mparams(r1, L, _, [2.0])),
    assertion(mparams(r2, L, _, [2.0])).

:- end_tests(dfrl_params).
