:- module(test_robot_bridge, []).
/** <module> robot_bridge.pl in plain swipl: a Prolog thread plays the Python host
*/
:- use_module(library(plunit)).
:- use_module('../../pybridge/robot_bridge').
:- use_module('../../pybridge/table_codec', [encode_values/3]).
:- use_module('../../platform_pl/robot_resources').

:- begin_tests(robot_bridge, [cleanup(bridge_shutdown)]).

%   serve_one(+Table, -Op): answer one request from Table (a qtable term) as
%   the host would, in this thread.
serve_one(qtable(Shape, Values), Op) :-
    bridge_next_request(request(Id, Op), 5),
    (   Op = write_table(_, _, _, _)
    ->  bridge_reply(Id, ok)
    ;   bridge_codec(Codec),
        encode_values(Codec, Values, Data),
        bridge_reply(Id, table(Shape, Data))
    ).

%   with_host(+Table, :Goal, -Ops): run Goal (which makes two requests)
%   while a host thread serves them; Ops are the requests it saw.
%   with_host/4 takes the number of requests.

with_host(Table, Goal, Ops) :-
    with_host(Table, Goal, Ops, 2).

with_host(Table, Goal, Ops, Count) :-
    thread_self(Me),
    thread_create(( findall(Op, (between(1, Count, _), serve_one(Table, Op)), Ops0),
                    thread_send_message(Me, served(Ops0)) ), Id, []),
    call_cleanup(call(Goal),
                 ( thread_get_message(served(Ops)),
                   thread_join(Id, _) )).

reset :-
    bridge_shutdown,
    bridge_set_codec(text),
    bridge_register_robot(r1, [algo(qlearning), shape([2, 2])]).

test(register, [setup(reset), Props == [algo(qlearning), shape([2, 2])]]) :-
    bridge_robot(r1, Props).
test(unregister, [setup(reset), fail]) :-
    bridge_unregister_robot(r1),
    bridge_robot(r1, _).
test(bad_props, [setup(reset), error(domain_error(robot_props, [algo(q)]))]) :-
    bridge_register_robot(r2, [algo(q)]).
test(bad_shape, [setup(reset), error(domain_error(_, [2]))]) :-
    bridge_register_robot(r2, [shape([2])]).

test(round_trip_text, [setup(reset), Got-Ops == qtable([2,2], [1.0,-0.0,5.0e-324,0.1])-[read_table(r1), write_table(r1, [2,2], text("1.0,-0.0,5.0e-324,0.1"), [])]]) :-
    T = qtable([2,2], [1.0,-0.0,5.0e-324,0.1]),
    with_host(T, (get_qtable(r1, Got), set_qtable(r1, Got)), Ops).
test(round_trip_fts, [setup(reset), Got == T]) :-
    bridge_set_codec(fts),
    T = qtable([2,2], [1.0,-0.0,5.0e-324,0.1]),
    with_host(T, (get_qtable(r1, Got), set_qtable(r1, Got)), [_, write_table(r1, [2,2], fts(S), [])]),
    fast_term_serialized(Values, S),
    assertion(Values == [1.0,-0.0,5.0e-324,0.1]).

test(steadfast_get, [setup(reset), fail]) :-
    with_host(qtable([2,2], [1.0,2.0,3.0,4.0]), get_qtable(r1, qtable([4,1], _)), _, 1).

test(qtable_and_visits, [setup(reset), T-V == qtable([2,2],[1.0,2.0,3.0,4.0])-qtable([2,2],[0.0,1.0,0.0,5.0])]) :-
    thread_create(( bridge_next_request(request(Id, read_table_and_visits(r1)), 5),
                    bridge_reply(Id, tables(table([2,2], text("1.0,2.0,3.0,4.0")),
                                            table([2,2], text("0,1,0,5")))) ), H, []),
    call_cleanup(get_qtable_and_visits(r1, T, V), thread_join(H, _)).

test(unknown_robot, [setup(reset), error(existence_error(robot, nobody))]) :-
    get_qtable(nobody, _).
%   The table a set sends is validated by the host (in Python, tests in
%   test_bridge_node.py); here it is only encoded and sent as it is.
test(set_sends_shape_and_values_as_given, [setup(reset),
        Ops == [write_table(r1, [4,1], text("1.0,2.0,3.0"), [])]]) :-
    with_host(qtable([2,2], []), set_qtable(r1, qtable([4,1], [1,2.0,3])), Ops, 1).
test(not_a_number, [setup(reset), error(type_error(number, x))]) :-
    set_qtable(r1, qtable([2,2], [1.0,2.0,3.0,x])).

test(unbound_table, [setup(reset), error(instantiation_error)]) :-
    set_qtable(r1, _).
test(unbound_shape, [setup(reset), error(instantiation_error)]) :-
    set_qtable(r1, qtable(_, [1.0, 2.0, 3.0, 4.0])).
test(not_a_qtable, [setup(reset), error(type_error(qtable, foo(1)))]) :-
    set_qtable(r1, foo(1)).
test(reply_of_wrong_size, [setup(reset), error(domain_error(qtable_size(4), 3))]) :-
    with_host(qtable([2,2], [1.0,2.0,3.0]), get_qtable(r1, _), _, 1).

test(resource_hook_lists_robots, [setup(reset), Props == [algo(qlearning), shape([2, 2])]]) :-
    hosted_robot(r1, Props).
test(resource_hook_reads_and_writes, [setup(reset),
        Got-Ops == qtable([2,2], [1.0,2.0,3.0,4.0])-[read_table(r1), write_table(r1, [2,2], text("1.0,2.0,3.0,4.0"), [round(3), agent(dfrl_q), epoch(2)])]]) :-
    T = qtable([2,2], [1.0,2.0,3.0,4.0]),
    with_host(T, ( get_robot_table(r1, Got, [timeout(5)]),
                   set_robot_table(r1, Got, [timeout(5), round(3), agent(dfrl_q), epoch(2),
                                             note(f(x))]) ), Ops).
test(resource_hook_tables, [setup(reset), T-V == qtable([2,2],[1.0,2.0,3.0,4.0])-qtable([2,2],[0.0,1.0,0.0,5.0])]) :-
    thread_create(( bridge_next_request(request(Id, read_table_and_visits(r1)), 5),
                    bridge_reply(Id, tables(table([2,2], text("1.0,2.0,3.0,4.0")),
                                            table([2,2], text("0,1,0,5")))) ), H, []),
    call_cleanup(get_robot_tables(r1, T, V, [timeout(5)]), thread_join(H, _)).
test(resource_hook_unknown_robot, [setup(reset), error(existence_error(robot, nobody))]) :-
    get_robot_table(nobody, _, []).
test(resource_hook_errors_pass_through, [setup(reset), error(timeout_error(bridge, r1))]) :-
    get_robot_table(r1, _, [timeout(0.05)]).

test(timeout, [setup(reset), error(timeout_error(bridge, r1))]) :-
    get_qtable(r1, _, [timeout(0.05)]).
test(timeout_flag, [setup(reset), error(timeout_error(bridge, r1)),
                    cleanup(set_prolog_flag(robot_bridge_timeout, 30.0))]) :-
    set_prolog_flag(robot_bridge_timeout, 0.05),
    get_qtable(r1, _).
test(expired_request_dropped, [setup(reset), fail]) :-
    catch(get_qtable(r1, _, [timeout(0.01)]), error(timeout_error(_, _), _), true),
    bridge_next_request(_, 0).
test(late_reply_ignored, [setup(reset)]) :-
    bridge_reply(123456, ok).

test(serving_thread_refused, [setup(reset), error(permission_error(wait, bridge_reply, _)),
                              cleanup(bridge_detach_server)]) :-
    bridge_attach_server,
    get_qtable(r1, _).

test(reply_error_is_thrown, [setup(reset), error(python_error('KeyError', "r1"))]) :-
    thread_create(( bridge_next_request(request(Id, _), 5),
                    bridge_reply(Id, error(python_error('KeyError', "r1"))) ), T, []),
    call_cleanup(get_qtable(r1, _), thread_join(T, _)).

test(shutdown_wakes_waiters, [setup(reset), Formal == existence_error(robot, r1)]) :-
    thread_self(Me),
    thread_create(( catch(get_qtable(r1, _), error(F, _), true),
                    thread_send_message(Me, formal(F)) ), T, []),
    wait_queued,
    bridge_shutdown,
    thread_get_message(formal(Formal)),
    thread_join(T, _).

%   The host's service queue is separate from the table queue: a service
%   request is served while a table request waits, and a shutdown answers
%   a waiting service caller.
test(service_queue_is_separate, [setup(reset), Reply-Pending == ok(json("{}"))-0]) :-
    thread_create(( bridge_next_service_request(request(Id, Op), 5),
                    assertion(Op == status),
                    bridge_reply(Id, ok(json("{}"))) ), H, []),
    bridge_service_call(status, Reply, [timeout(5)]),
    thread_join(H, _),
    message_queue_property(robot_bridge_requests, size(Pending)).
test(service_call_times_out, [setup(reset), error(timeout_error(robot_service, host))]) :-
    bridge_service_call(status, _, [timeout(0.1)]).
test(service_call_after_shutdown, [setup(reset), error(existence_error(robot_service, host))]) :-
    bridge_shutdown,
    bridge_service_call(status, _, [timeout(1)]).

test(messages, [setup(reset)]) :-
    message_to_codes(error(timeout_error(bridge, r1), _), Text1),
    once(sub_string(Text1, _, _, _, "robot host")),
    message_to_codes(error(python_error('ValueError', "bad"), _), Text2),
    once(sub_string(Text2, _, _, _, "ValueError")).

message_to_codes(Term, Text) :-
    message_to_codes(Term, [], Codes), string_codes(Text, Codes).
message_to_codes(Term, _, Codes) :-
    '$messages':translate_message(Term, Lines, []),
    with_output_to(codes(Codes), print_message_lines(current_output, '', Lines)).

wait_queued :-
    between(1, 500, _),
    (   message_queue_property(robot_bridge_requests, size(N)),
        N > 0
    ->  !
    ;   sleep(0.01),
        fail
    ).

:- end_tests(robot_bridge).

%   Parameter vectors: a robot that offers params(Layout, Samples, Values)
%   (a function learner has no table), the ops the host sees, the hook.
:- begin_tests(robot_bridge_params, [cleanup(bridge_shutdown)]).

preset :-
    bridge_shutdown,
    bridge_set_codec(text),
    bridge_register_robot(f1, [algo(dqn), learner(function),
                               layout([w-[1,2], b-[1]])]).

%   serve_params(-Op): answer one request with the 3 values below
serve_params(Op) :-
    bridge_next_request(request(Id, Op), 5),
    (   Op = write_params(_, _, _, _)
    ->  bridge_reply(Id, ok)
    ;   bridge_reply(Id, params([w-[1,2], b-[1]], 7, text("0.5,-1.0,2.0")))
    ).

with_params_host(Goal, Ops, Count) :-
    thread_self(Me),
    thread_create(( findall(Op, (between(1, Count, _), serve_params(Op)), Ops0),
                    thread_send_message(Me, served(Ops0)) ), Id, []),
    call_cleanup(call(Goal),
                 ( thread_get_message(served(Ops)),
                   thread_join(Id, _) )).

test(register_layout_only, [setup(preset),
        Props == [algo(dqn), learner(function), layout([w-[1,2], b-[1]])]]) :-
    hosted_robot(f1, Props).
test(bad_layout, [setup(preset), error(domain_error(param_layout, [w-[x]]))]) :-
    bridge_register_robot(f2, [layout([w-[x]])]).
test(empty_layout, [setup(preset), error(domain_error(param_layout, [w-[0]]))]) :-
    bridge_register_robot(f2, [layout([w-[0]])]).

test(params_round_trip, [setup(preset),
        Got-Ops == params([w-[1,2], b-[1]], 7, [0.5,-1.0,2.0])-
                   [ read_params(f1),
                     write_params(f1, [w-[1,2], b-[1]], text("0.5,-1.0,2.0"),
                                [round(2), agent(fed_dqn)]) ]]) :-
    with_params_host(( get_robot_params(f1, Got, [timeout(5)]),
                       Got = params(L, _, V),
                       set_robot_params(f1, params(L, V),
                                        [timeout(5), round(2), agent(fed_dqn)]) ),
                     Ops, 2).
test(params_fts, [setup(preset)]) :-
    bridge_set_codec(fts),
    with_params_host(set_params(f1, params([w-[1,2], b-[1]], [1, 2.5, -0.0])), [Op], 1),
    Op = write_params(f1, _, fts(S), []),
    fast_term_serialized(Values, S),
    assertion(Values == [1.0, 2.5, -0.0]).

test(no_table_on_a_function_learner, [setup(preset), error(existence_error(qtable, f1))]) :-
    get_qtable(f1, _).
test(no_table_write_either, [setup(preset), error(existence_error(qtable, f1))]) :-
    set_robot_table(f1, qtable([1,1], [1.0]), []).
test(no_params_on_a_table_robot, [setup(( preset,
        bridge_register_robot(r1, [algo(q), shape([2, 2]), learner(tabular)]) )),
        error(existence_error(params, r1))]) :-
    get_robot_params(r1, _, []).
test(params_unknown_robot, [setup(preset), error(existence_error(robot, nobody))]) :-
    get_params(nobody, _).
test(not_params, [setup(preset), error(type_error(params, qtable([3], [1.0])))]) :-
    set_params(f1, qtable([3], [1.0])).
test(params_not_a_number, [setup(preset), error(type_error(number, x))]) :-
    set_params(f1, params([w-[1,2], b-[1]], [1.0, x, 2.0])).
test(params_reply_of_wrong_size, [setup(preset), error(domain_error(params_size(3), 2))]) :-
    thread_create(( bridge_next_request(request(Id, _), 5),
                    bridge_reply(Id, params([w-[1,2], b-[1]], 1, text("1.0,2.0"))) ), H, []),
    call_cleanup(get_params(f1, _), thread_join(H, _)).
test(steadfast_get_params, [setup(preset), fail]) :-
    with_params_host(get_params(f1, params([w-[3]], _, _)), _, 1).
test(params_timeout, [setup(preset), error(timeout_error(bridge, f1))]) :-
    get_robot_params(f1, _, [timeout(0.05)]).

:- end_tests(robot_bridge_params).
