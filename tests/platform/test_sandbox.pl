/*  plunit tests of the mobile-code sandbox (code_safety.pl): what a peer
    sends (an agent record, a program, a post) is refused when unsafe and
    nothing of it is installed; the agent API, Tartarus programs and the
    dFRL aggregation methods pass. Nodes in one process, requests over TCP.
*/
:- use_module('../../platform_pl/tartarus').
:- use_module('../../platform_pl/transport').
:- use_module('../../platform_pl/code_safety').
:- use_module('../../platform_pl/dfrl_agent/dfrl_agent').
:- use_module(library(plunit)).
:- use_module(library(readutil)).
:- use_module('../../platform_pl/agents', [agent_create/4]).
:- use_module('../../platform_pl/codeload', [program_module/2]).

:- prolog_load_context(directory, D), asserta(user:sandbox_test_dir(D)).

here(Rel, Abs) :- user:sandbox_test_dir(D), atomic_list_concat([D, /, Rel], Abs).

:- dynamic user:sandbox_seen/1.
user:node_label(test).                  % what the Tartarus tour's nodes define

record(Clauses, agent(a1, h, mobile, [], [], [], Clauses, [])).

refused(Clauses, Culprit) :-
    record(Clauses, R),
    catch(check_agent_record(R), error(permission_error(install, code, Culprit), _), true),
    nonvar(Culprit).

accepted(Clauses) :-
    record(Clauses, R),
    check_agent_record(R).

port(Node, Port) :- node_property(Node, address(_:Port)).
stop_all(Nodes) :- forall(member(N, Nodes), catch(node_stop(N), _, true)).

wait_for(Goal) :- wait_for(Goal, 100).
wait_for(Goal, N) :-
    (   call(Goal) -> true
    ;   N > 0 -> sleep(0.02), N1 is N - 1, wait_for(Goal, N1)
    ;   fail
    ).

:- begin_tests(agent_records).

test(shell) :- refused([(h(a1, _, main) :- shell('id'))], shell(_, _)).
test(open_file) :- refused([(h(a1, _, main) :- open('/etc/passwd', read, _))], open(_, _, _)).
test(halt) :- refused([(h(a1, _, main) :- halt)], halt(_)).
test(assert_into_user) :- refused([(h(a1, _, main) :- assertz(user:x(1)))], assertz(user:x(1))).
test(assert_rule) :- refused([(h(a1, _, main) :- assertz((x(1) :- shell(ls))))], assertz(_)).
test(change_tokens) :- refused([(h(a1, _, main) :- set_token(evil))], tartarus:set_token/1).
test(node_tokens) :- refused([(h(a1, _, main) :- node_set_tokens(_, [evil]))], node:node_set_tokens/2).
test(install_request_handler) :-
    refused([(h(a1, _, main) :- assertz(node:platform_request(x, _, ok(y), true)))], assertz(_)).
test(op) :- refused([(h(a1, _, main) :- op(700, xfx, ===>))], op(_, _, _)).
test(foreign_or_platform_internals) :-
    refused([(h(a1, _, main) :- M = transport, call(M:transport_request(a, b, c, d)))],
            transport:transport_request/4).
test(call_of_unknown_goal) :- refused([(h(a1, _, G) :- call(G))], unknown_call(_)).
test(call_bound_in_conjunction) :- refused([(h(a1, _, main) :- X = shell(ls), call(X))], shell(_, _)).
test(helper_calls_shell) :- refused([(h(a1, _, main) :- helper), (helper :- shell(ls))], shell(_, _)).
test(undefined) :- refused([(h(a1, _, main) :- no_such_predicate(3))], undefined(_, _)).
test(read_tokens) :-
    refused([(h(a1, _, main) :- agent_property(_, a1, tokens(T)), writeln(T))], agent_registry:agent_property/3).
test(move_another_agent) :- refused([(h(a1, L, main) :- move_agent(fed_q, L))], tartarus:move_agent/2).
test(handler_not_its_own) :- refused([foo(1)], handler(h)).
test(control_construct_head) :-
    refused([((x :- shell(ls)) :- true), (h(a1, _, main) :- true)], clause_head(_)).
test(declare_platform_event) :- refused([(h(a1, _, main) :- platform_event(user:shell/2))], messages:platform_event/1).
test(load_code_from_agent) :- refused([(h(a1, _, main) :- load_program_text(x, y, "", []))], codeload:load_program_text/4).

test(agent_api_and_output) :-
    accepted([ (h(a1, L, main) :- format("at ~w~n", [L]), nl, flush_output,
                                   retract(count(a1, N)), N1 is N + 1, assertz(count(a1, N1)),
                                   reverse([a, b], R), msort(R, _),
                                   post_agent(platform, L, [m, m, L, hi]),
                                   agent_hop_times(a1, _),
                                   move_agent(a1, L)),
               (h(Me, L, stop) :- clone_agent(Me, L, _), purge_agent(Me)),
               count(a1, 0) ]).
%   node.pl re-exports them from node_registry.pl: the API names where
%   they are defined.
test(node_api) :-
    accepted([ (h(a1, _, main) :- current_node(N), node_property(N, address(A)), writeln(A)),
               count(a1, 0) ]).
%   agents.pl re-exports them from agent_registry.pl, agent_code.pl and
%   agent_execution.pl: the API names where they are defined.
test(agents_api) :-
    accepted([ (h(a1, _, main) :- agents:current_agent(Me),
                                   agents:agent_property(_, Me, status(_)),
                                   agents:agent_exists(_, a1), agents:agent_list(_, _),
                                   agents:agent_hop_times(_, a1, _),
                                   agents:agent_add_payload(_, a1, [count/2]),
                                   agents:agent_add_facts(_, a1, [seen(1)]),
                                   agents:agent_remove_payload(_, a1, [seen/1])),
               count(a1, 0) ]).
test(robot_params_api) :-
    accepted([ (h(a1, _, main) :- robot_resources:hosted_robot(r1, _),
                                   robot_resources:get_robot_params(r1, params(L, _, V), []),
                                   robot_resources:set_robot_params(r1, params(L, V), [])) ]).
test(dfrl_params_agent_record) :-
    node_start(localhost:0, N, [token(7), default(false)]),
    call_cleanup(( tmp_file(log, Log),
                   dfrl_create(N, dfp, plan([stop(localhost, 1, r1)], 1, 0.0, Log, 5),
                               [carries(params)]),
                   agents:agent_export(N, dfp, R),
                   check_agent_record(R) ),
                 stop_all([N])).
test(dfrl_agent_record) :-
    nb_setval(sandbox_tmp, none),
    node_start(localhost:0, N, [token(7), default(false)]),
    call_cleanup(( tmp_file(log, Log),
                   dfrl_create(N, dfa, plan([stop(localhost, 1, r1)], 1, 0.0, Log, 5), []),
                   agents:agent_export(N, dfa, R),
                   check_agent_record(R) ),
                 stop_all([N])).

:- end_tests(agent_records).

:- begin_tests(arrivals).

%   An attacker's transfer: a record with a shell handler, no seal.
raw_transfer(Dst, Record, Reply) :-
    node_property(Dst, address(DstAddr)),
    get_time(T),
    transport_open(DstAddr, Conn, []),
    call_cleanup(( transport_auth(Conn, [k], enter),
                   transport_send(Conn, binary,
                                  transfer(m_evil, move, localhost:1, T, Record, inc)),
                   transport_receive(Conn, Reply, []) ),
                 transport_close(Conn)).

test(refused_agent_is_not_installed, [cleanup(stop_all([B]))]) :-
    node_start(localhost:0, B, [token(k), default(false)]),
    Record = agent(evil, h, mobile, [], [], [h/3], [(h(evil, _, main) :- shell('touch /tmp/dfrl_pwned'))], []),
    raw_transfer(B, Record, Reply),
    assertion(Reply = error(error(permission_error(install, code, shell(_, _)), _))),
    assertion(\+ agents:agent_exists(B, evil)),
    % the node still serves: a safe agent arrives
    Good = agent(good, h, mobile, [], [], [h/3], [(h(good, _, main) :- true)], []),
    raw_transfer(B, Good, Reply2),
    assertion(Reply2 == ok(staged(good))).

test(forged_seal_is_checked, [cleanup(stop_all([B]))]) :-
    node_start(localhost:0, B, [token(k), default(false)]),
    Record = agent(evil, h, mobile, same_process(forged), [], [h/3],
                   [(h(evil, _, main) :- halt)], []),
    raw_transfer(B, Record, Reply),
    assertion(Reply = error(error(permission_error(install, code, halt(_)), _))).

test(arriving_agent_gets_the_nodes_tokens, [cleanup(stop_all([B]))]) :-
    node_start(localhost:0, B, [token(k), default(false)]),
    Good = agent(good, h, mobile, [stolen], [], [h/3], [(h(good, _, main) :- true)], []),
    raw_transfer(B, Good, Reply),
    assertion(Reply == ok(staged(good))),
    agent_property(B, good, tokens(T)),
    assertion(T == [k]).

:- end_tests(arrivals).

:- begin_tests(programs).

test(refused_program_loads_nothing, [cleanup(stop_all([N]))]) :-
    node_start(localhost:0, N, [token(k), default(false)]),
    port(N, P),
    forall(member(Text, [ "sandbox_marker(1).\n:- initialization(shell('touch /tmp/dfrl_pwned')).\n",
                          "sandbox_marker(1).\nevil :- open('/tmp/dfrl_pwned', write, _).\n",
                          "sandbox_marker(1).\n:- halt.\n",
                          "sandbox_marker(1).\n:- op(700, xfx, ===>).\n",
                          "sandbox_marker(1).\nuser:message_hook(_, _, _) :- true.\n",
                          "sandbox_marker(1).\nnode:platform_request(x, _, ok(y), true).\n",
                          "sandbox_marker(1).\nmove_agent(_, _).\n",
                          "sandbox_marker(1).\n:- set_token(evil).\n" ]),
           ( catch(load_program_text(localhost:P, evil, Text, [tokens([k])]), E, true),
             assertion(subsumes_term(error(permission_error(install, code, _), _), E)),
             program_module(evil, Evil),
             assertion(\+ catch(Evil:sandbox_marker(_), _, fail)) )),
    assertion(\+ exists_file('/tmp/dfrl_pwned')),
    load_program_text(localhost:P, good, "sandbox_marker(1).\n", [tokens([k])]),
    program_module(good, M),
    assertion(M:sandbox_marker(1)).

test(hook_clause_alone) :-                  % no user predicate in the program
    check_program_text(hook_only,
                       "dfrl_aggregation:aggregate_step(s, A, T, B) :- sleep(0.01), A = T, B = T.").

test(method_for_params_declares_it) :-       % a method that applies to parameters
    check_program_text(params_method,
                       "dfrl_aggregation:method_applies(trimmed, params).\n\c
                        dfrl_aggregation:aggregate_init(trimmed, params(_, _, V), V).").

test(hook_of_the_old_module_is_told_where_it_went) :-
    % the culprit names the new predicate: it is what reaches the sender
    catch(check_program_text(old_hook,
                             "dfrl_agent:aggregate_init(m, _, none)."), E, true),
    assertion(subsumes_term(error(permission_error(install, code,
                                                   moved_hook(dfrl_agent:aggregate_init/3,
                                                              dfrl_aggregation:aggregate_init/3)),
                                  _), E)),
    platform_errors:message_text(E, Text),
    assertion(sub_string(Text, _, _, _, "which is dfrl_aggregation:aggregate_init/3 now")),
    catch(check_program_text(old_decl, ":- multifile dfrl_agent:aggregate_step/4."), E2, true),
    assertion(subsumes_term(error(permission_error(install, code,
                                                   moved_hook(dfrl_agent:aggregate_step/4, _)),
                                  _), E2)),
    catch(check_program_text(old_call,
                             "dfrl_aggregation:aggregate_step(m, A, T, B) :- \c
                              dfrl_agent:aggregate_step(average, A, T, B)."), E4, true),
    assertion(subsumes_term(error(permission_error(install, code,
                                                   moved_hook(dfrl_agent:aggregate_step/4,
                                                              dfrl_aggregation:aggregate_step/4)),
                                  _), E4)),
    catch(check_program_text(other, "lists:append(_, _, _)."), E3, true),
    E3 = error(_, context(_, Why3)),
    assertion(Why3 == 'a clause for another module').

test(aggregation_methods_pass) :-
    forall(member(F0, ['../../platform_pl/dfrl_agent/examples/max_visited.pl',
                       '../../platform_pl/dfrl_agent/examples/median_method.pl',
                       '../../platform_pl/examples/tartarus_tour/tour.pl',
                       '../experiments/driver/launcher/slow_method.pl']),
           ( here(F0, F),
             read_file_to_string(F, Text, []),
             file_base_name(F, Id),
             check_program_text(Id, Text) )).

test(injected_method_loads_over_the_network, [cleanup(stop_all([N]))]) :-
    node_start(localhost:0, N, [token(k), default(false)]),
    port(N, P),
    here('../../platform_pl/dfrl_agent/examples/max_visited.pl', F),
    load_program_at(localhost:P, F, [tokens([k])]),
    assertion(dfrl_method(max_visited)).

:- end_tests(programs).

:- begin_tests(posts).

:- dynamic user:sbx/3, user:sbx/4.
user:sbx(guid, _, main).
user:sbx(guid, _, Text, _) :- assertz(user:sandbox_seen(Text)).

test(declared_event_reaches_the_agent, [cleanup(stop_all([A,B]))]) :-
    node_start(localhost:0, A, [token(k), default(false)]),
    node_start(localhost:0, B, [token(k), default(false)]),
    port(B, PB),
    with_node(B, create_mobile_agent(s1, sbx, [k])),
    with_node(A, post_agent(platform, (localhost, PB), [sbx, s1, (localhost, PB), hello, x])),
    assertion(wait_for(user:sandbox_seen(hello))).

test(undeclared_events_are_refused, [cleanup(stop_all([A,B]))]) :-
    node_start(localhost:0, A, [token(k), default(false)]),
    node_start(localhost:0, B, [token(k), default(false)]),
    port(B, PB),
    with_node(B, create_mobile_agent(s2, sbx, [k])),
    with_node(B, agent_create(s3, sbx, [events([sbx/4])], B)),
    % an agent that declares its events: its start event (arity 3) is not one
    catch(with_node(A, post_agent(platform, (localhost, PB), [sbx, s3, x, main])), E1, true),
    assertion(subsumes_term(error(permission_error(post, event, sbx/3), _), E1)),
    with_node(A, post_agent(platform, (localhost, PB), [sbx, s3, x, declared, y])),
    assertion(wait_for(user:sandbox_seen(declared))),
    % an arity it does not define, a handler it does not have
    catch(with_node(A, post_agent(platform, (localhost, PB), [sbx, s2, x, a, b, c])), E2, true),
    assertion(subsumes_term(error(permission_error(post, event, sbx/5), _), E2)),
    catch(with_node(A, post_agent(platform, (localhost, PB), [shell, s2, x, y])), E4, true),
    assertion(subsumes_term(error(existence_error(agent, s2), _), E4)),
    catch(with_node(A, post_agent(platform, (localhost, PB), [shell, platform, x, 'id'])), E3, true),
    assertion(subsumes_term(error(existence_error(agent, platform), _), E3)).

:- end_tests(posts).

:- begin_tests(trust).

test(trusted_by_name, [cleanup(stop_all([N]))]) :-
    node_start(localhost:0, N, [default(false), token(test), trusted_peers([alice, "bob"])]),
    assertion(peer_trusted(N, alice)),
    assertion(peer_trusted(N, bob)),
    assertion(\+ peer_trusted(N, mallory)).

test(nobody_trusted_by_default, [cleanup(stop_all([N]))]) :-
    node_start(localhost:0, N, [default(false), token(test)]),
    assertion(\+ peer_trusted(N, alice)).

test(seal_is_bound_to_migration_and_record) :-
    R = agent(a, h, mobile, [], [], [], [h(a, _, main)], []),
    record_seal(m1, R, S),
    assertion(record_sealed(m1, R, S)),
    assertion(\+ record_sealed(m2, R, S)),
    R2 = agent(a, h, mobile, [], [], [], [(h(a, _, main) :- halt)], []),
    assertion(\+ record_sealed(m1, R2, S)).

:- end_tests(trust).
