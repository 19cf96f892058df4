/*  plunit tests of the agent platform: several nodes in one process, on
    OS-chosen localhost ports. Run: swipl -g run_tests -t halt test_platform.pl
*/
:- use_module('../../platform_pl/tartarus').
:- use_module('../../platform_pl/wire').
:- use_module('../../platform_pl/transport').
:- use_module(library(plunit)).
:- use_module(library(socket)).

:- dynamic walker/3, trail/2, got/1, echo/4, pinger/3, counter/2, cloner/3,
           user:seen/2, user:msg/2, user:event_seen/1.

% --- agent programs, Tartarus style ----------------------------------

trail(guid, []).

walker(guid, (_Ip, Port), main) :-
    retract(trail(guid, T0)),
    T = [Port|T0],
    assertz(trail(guid, T)),
    user:route(Route),
    length(T, N),
    (   nth1(N, Route, _), N < 4
    ->  nth1(N, Route, Next0), N1 is N + 1, nth1(N1, Route, Next0b),
        Next = Next0b, _ = Next0,
        move_agent(guid, (localhost, Next))
    ;   assertz(user:seen(guid, T))
    ).

echo(guid, _Link, Text, From) :-
    assertz(user:msg(guid, Text-From)).

counter(guid, 0).
cloner(guid, (_, Port), main) :-
    retract(counter(guid, C0)), C is C0 + 1, assertz(counter(guid, C)),
    assertz(user:seen(guid, at(Port, C))).

user:platform_hello(platform, _Link, X) :-
    assertz(user:event_seen(X)).

:- dynamic user:route/1.

wait_for(Goal) :- wait_for(Goal, 100).
wait_for(Goal, N) :-
    (   call(Goal) -> true
    ;   N > 0 -> sleep(0.02), N1 is N - 1, wait_for(Goal, N1)
    ;   fail
    ).

start3(A, B, C) :-
    node_start(localhost:0, A, [token(secret), default(false)]),
    node_start(localhost:0, B, [token(secret), default(false)]),
    node_start(localhost:0, C, [token(secret), default(false)]).

stop_all(Nodes) :- forall(member(N, Nodes), catch(node_stop(N), _, true)).

port(Node, Port) :- node_property(Node, address(_:Port)).

:- begin_tests(addresses).

test(out_of_range_port, error(domain_error(port, 70000))) :-
    node_start(localhost:70000, _, []).
test(negative_port, error(domain_error(port, -1))) :-
    node_start(localhost:(-1), _, []).
test(bad_address, error(type_error(address, foo(bar)))) :-
    node_start(foo(bar), _, []).
test(port_zero_chooses, [true(P > 0), cleanup(node_stop(N))]) :-
    node_start(localhost:0, N, [default(false), token(test)]),
    port(N, P).
test(port_in_use, [ setup(node_start(localhost:0, N, [default(false), token(test)])),
                    cleanup(node_stop(N)),
                    error(socket_error(_, _))
                  ]) :-
    port(N, P),
    node_start(localhost:P, _, [default(false), token(test)]).

:- end_tests(addresses).

:- begin_tests(guid).

test(replace_on_terms) :-
    agents:replace_guid(f(guid, "guid", 'my_guid_x', [guid|T], g(guid)), guid, a1, R),
    R == f(a1, "guid", 'my_guid_x', [a1|T], g(a1)).

:- end_tests(guid).

:- begin_tests(itinerary, [cleanup(retractall(user:seen(_, _)))]).

test(three_nodes_and_home, [cleanup(stop_all([A,B,C]))]) :-
    start3(A, B, C),
    maplist(port, [A,B,C], [PA,PB,PC]),
    retractall(user:route(_)),
    assertz(user:route([PA,PB,PC,PA])),
    with_node(A, ( create_mobile_agent(w1, (localhost,PA), walker, [secret]),
                   add_payload(w1, [(trail,2)]),
                   execute_agent(w1, (localhost,PA), walker) )),
    assertion(wait_for(user:seen(w1, _))),
    user:seen(w1, Trail),
    assertion(Trail == [PA,PC,PB,PA]),
    with_node(A, list_agents(Names)),
    assertion(Names == [w1]),
    with_node(B, list_agents(NB)),
    assertion(NB == []),
    with_node(A, agent_hop_times(w1, Ms)),
    assertion(length(Ms, 3)).

test(refused_token_keeps_agent, [cleanup(stop_all([A,B]))]) :-
    node_start(localhost:0, A, [token(one), default(false)]),
    node_start(localhost:0, B, [token(two), default(false)]),
    port(B, PB),
    with_node(A, create_mobile_agent(t1, walker, [one])),
    catch(with_node(A, move_agent(t1, (localhost, PB))), E, true),
    assertion(subsumes_term(error(permission_error(enter, platform, _), _), E)),
    with_node(A, list_agents(Names)),
    assertion(Names == [t1]),
    with_node(B, list_agents(NB)),
    assertion(NB == []).

test(unreachable_node_keeps_agent, [cleanup(stop_all([A]))]) :-
    node_start(localhost:0, A, [default(false), token(test)]),
    node_start(localhost:0, Gone, [default(false), token(test)]),
    port(Gone, PG),
    node_stop(Gone),
    with_node(A, create_mobile_agent(u1, walker, [])),
    catch(with_node(A, move_agent(u1, (localhost, PG))), E, true),
    assertion(subsumes_term(error(transport_error(_, connect(_)), _), E)),
    with_node(A, list_agents([u1])).

test(static_agent_does_not_move, [cleanup(stop_all([A,B]))]) :-
    node_start(localhost:0, A, [default(false), token(test)]),
    node_start(localhost:0, B, [default(false), token(test)]),
    port(B, PB),
    with_node(A, create_static_agent(s1, walker, [])),
    catch(with_node(A, move_agent(s1, (localhost,PB))), E, true),
    assertion(subsumes_term(error(permission_error(move, static_agent, s1), _), E)).

:- end_tests(itinerary).

:- dynamic bouncer/3, bounces/2.
bounces(guid, 0).
bouncer(guid, (_, Port), main) :-
    retract(bounces(guid, N0)), N is N0 + 1, assertz(bounces(guid, N)),
    user:pair(P1, P2),
    (   N >= 40 -> assertz(user:seen(guid, bounced(N)))
    ;   Port =:= P1 -> move_agent(guid, (localhost, P2))
    ;   move_agent(guid, (localhost, P1))
    ).
:- dynamic user:pair/2.

:- begin_tests(bounce, [cleanup(retractall(user:seen(_, _)))]).

% An agent that comes straight back must never find its old copy still
% registered at the node it left (regression: the source removed its copy
% only after sending the commit).
test(straight_back_forty_times, [cleanup(stop_all([A,B]))]) :-
    node_start(localhost:0, A, [default(false), token(test)]),
    node_start(localhost:0, B, [default(false), token(test)]),
    port(A, PA), port(B, PB),
    retractall(user:pair(_, _)), assertz(user:pair(PA, PB)),
    with_node(A, ( create_mobile_agent(b1, bouncer, []),
                   add_payload(b1, [(bounces,2)]),
                   execute_agent(b1, (localhost,PA), bouncer) )),
    assertion(wait_for(user:seen(b1, bounced(40)))).

:- end_tests(bounce).

:- begin_tests(clone_post, [cleanup(retractall(user:seen(_, _)))]).

test(clone_runs_with_own_name, [cleanup(stop_all([A,B]))]) :-
    node_start(localhost:0, A, [token(k), default(false)]),
    node_start(localhost:0, B, [token(k), default(false)]),
    port(B, PB),
    with_node(A, ( create_mobile_agent(c1, cloner, [k]),
                   add_payload(c1, [(counter,2)]),
                   clone_agent(c1, (localhost,PB), Clone) )),
    assertion(Clone \== c1),
    assertion(wait_for(user:seen(Clone, at(PB, 1)))),
    with_node(A, list_agents(LA)),
    assertion(LA == [c1]),
    with_node(B, list_agents(LB)),
    assertion(LB == [Clone]).

test(post_reaches_handler, [cleanup(stop_all([A,B]))]) :-
    node_start(localhost:0, A, [default(false), token(test)]),
    node_start(localhost:0, B, [default(false), token(test)]),
    port(B, PB),
    with_node(B, create_mobile_agent(e1, echo, [])),
    with_node(A, post_agent(platform, (localhost,PB), [echo, e1, (localhost,PB), hi, there])),
    assertion(wait_for(user:msg(e1, hi-there))).

test(post_to_unknown_agent, [cleanup(stop_all([A,B]))]) :-
    node_start(localhost:0, A, [default(false), token(test)]),
    node_start(localhost:0, B, [default(false), token(test)]),
    port(B, PB),
    catch(with_node(A, post_agent(platform, (localhost,PB), [echo, nobody, x, y, z])), E, true),
    assertion(subsumes_term(error(existence_error(agent, nobody), _), E)).

test(post_cannot_call_arbitrary_goal, [cleanup(stop_all([B]))]) :-
    node_start(localhost:0, B, [default(false), token(test)]),
    port(B, PB),
    catch(transport_request(localhost:PB, post(platform, assertz, x, [user:pwned]), _, []),
          E, true),
    assertion(nonvar(E)),
    assertion(\+ catch(user:pwned, _, fail)),
    catch(transport_request(localhost:PB, call(assertz(user:pwned)), _, []), E2, true),
    assertion(subsumes_term(error(domain_error(platform_request, _), _), E2)),
    assertion(\+ catch(user:pwned, _, fail)).

test(declared_platform_event, [cleanup(stop_all([B]))]) :-
    node_start(localhost:0, B, [default(false), token(test)]),
    port(B, PB),
    platform_event(platform_hello/3),
    post_agent(platform, (localhost,PB), [platform_hello, platform, (localhost,PB), 42]),
    assertion(wait_for(user:event_seen(42))).

:- end_tests(clone_post).

:- begin_tests(bad_input).

raw_send(Port, Bytes, Reply) :-
    setup_call_cleanup(
        tcp_connect(localhost:Port, Pair, []),
        ( stream_pair(Pair, In, Out),
          set_stream(In, type(binary)), set_stream(Out, type(binary)),
          set_stream(In, timeout(5)),
          frame_read(In, _Hello, []),
          forall(member(B, Bytes), put_byte(Out, B)),
          flush_output(Out),
          catch(frame_read(In, Reply, [max_size(100000)]), _, Reply = closed)
        ),
        close(Pair, [force(true)])).

alive(Port) :-
    transport_request(localhost:Port, ping, pong(_), []).

test(bad_magic_gets_error_and_node_serves, [cleanup(stop_all([N]))]) :-
    node_start(localhost:0, N, [default(false), token(test)]),
    port(N, P),
    raw_send(P, `GET / HTTP/1.0\r\n\r\n`, R),
    assertion(R = frame(text, error(error(wire_error(bad_magic), _)))),
    assertion(alive(P)).

test(oversized_frame_refused, [cleanup(stop_all([N]))]) :-
    node_start(localhost:0, N, [default(false), token(test), max_text_frame_size(1000)]),
    port(N, P),
    raw_send(P, [0'D,0'F,0'R,0'L,1,0'T,0,0, 0x7f,0xff,0xff,0xff], R),
    assertion(R = frame(text, error(error(wire_error(too_large(_, 1000)), _)))),
    assertion(alive(P)).

test(binary_without_token_refused, [cleanup(stop_all([N]))]) :-
    node_start(localhost:0, N, [token(s3cret), default(false)]),
    port(N, P),
    raw_send(P, [0'D,0'F,0'R,0'L,1,0'B,0,0, 0,0,0,4, 1,2,3,4], R),
    assertion(R = frame(text, error(error(wire_error(binary_not_allowed), _)))),
    assertion(alive(P)).

test(syntax_error_in_text_frame, [cleanup(stop_all([N]))]) :-
    node_start(localhost:0, N, [default(false), token(test)]),
    port(N, P),
    Body = `foo(((( .`,
    length(Body, L),
    raw_send(P, [0'D,0'F,0'R,0'L,1,0'T,0,0, 0,0,0,L|Body], R),
    assertion(R = frame(text, error(error(wire_error(syntax(_)), _)))),
    assertion(alive(P)).

test(port_scan_and_idle_connections, [cleanup(stop_all([N]))]) :-
    node_start(localhost:0, N, [default(false), token(test), idle_timeout(1)]),
    port(N, P),
    forall(between(1, 20, _),
           ( tcp_connect(localhost:P, S, []), close(S, [force(true)]) )),
    findall(S2, ( between(1, 10, _), tcp_connect(localhost:P, S2, []) ), Idle),
    assertion(alive(P)),
    forall(member(S3, Idle), close(S3, [force(true)])).

test(truncated_frame, [cleanup(stop_all([N]))]) :-
    node_start(localhost:0, N, [default(false), token(test)]),
    port(N, P),
    setup_call_cleanup(
        tcp_connect(localhost:P, Pair, []),
        ( stream_pair(Pair, _, Out), set_stream(Out, type(binary)),
          forall(member(B, [0'D,0'F,0'R,0'L,1,0'T,0,0,0,0,0,100, 0'a]), put_byte(Out, B)),
          flush_output(Out) ),
        close(Pair, [force(true)])),
    assertion(alive(P)).

test(unknown_request, [cleanup(stop_all([N]))]) :-
    node_start(localhost:0, N, [default(false), token(test)]),
    port(N, P),
    catch(transport_request(localhost:P, shell('rm -rf /'), _, []), E, true),
    assertion(subsumes_term(error(domain_error(platform_request, _), _), E)).

test(remote_load_needs_token, [cleanup(stop_all([N]))]) :-
    node_start(localhost:0, N, [token(abc), default(false)]),
    port(N, P),
    catch(load_program_text(localhost:P, x, "injected(1).", [tokens([wrong])]), E, true),
    assertion(subsumes_term(error(permission_error(load, platform, _), _), E)),
    assertion(\+ catch('dfrl_program://x':injected(_), _, fail)),
    load_program_text(localhost:P, x, "injected(1).", [tokens([abc])]),
    assertion('dfrl_program://x':injected(1)).   % a peer's program loads into its own module

:- end_tests(bad_input).

:- begin_tests(lost_messages).

%   Play the source of a migration by hand: send the transfer, get the
%   staged answer, then drop the connection without the commit.
transfer_without_commit(Src, Dst, Name, MigId) :-
    agents:agent_export(Src, Name, Record),
    setarg(4, Record, []),                      % sealed as a node of this process does
    code_safety:record_seal(MigId, Record, Seal),
    setarg(4, Record, same_process(Seal)),
    node_property(Src, address(SrcAddr)),
    node_property(Dst, address(DstAddr)),
    get_time(T),
    transport_open(DstAddr, Conn, []),
    transport_auth(Conn, [k], enter),
    transport_send(Conn, binary, transfer(MigId, move, SrcAddr, T, Record)),
    transport_receive(Conn, Reply, []),
    transport_close(Conn),
    assertion(Reply = ok(staged(Name))).

lost_setup(A, B) :-
    node_start(localhost:0, A, [token(k), default(false), connect_timeout(1)]),
    node_start(localhost:0, B, [token(k), default(false), connect_timeout(1),
                                commit_timeout(1)]),
    with_node(A, ( create_mobile_agent(lm, cloner, [k]), add_payload(lm, [(counter,2)]) )).

test(lost_commit_source_committed, [cleanup(stop_all([A,B]))]) :-
    lost_setup(A, B),
    migration:decide(A, m1, committed),
    transfer_without_commit(A, B, lm, m1),
    assertion(wait_for(user:seen(lm, at(_, _)))),
    with_node(B, list_agents(L)),
    assertion(L == [lm]).

test(lost_commit_source_aborted, [cleanup(stop_all([A,B]))]) :-
    lost_setup(A, B),
    migration:decide(A, m2, aborted),
    transfer_without_commit(A, B, lm, m2),
    assertion(wait_for(( with_node(B, list_agents(L)), L == [] ))),
    with_node(A, list_agents(LA)),
    assertion(LA == [lm]).

test(lost_commit_source_silent, [cleanup(stop_all([A,B]))]) :-
    lost_setup(A, B),
    transfer_without_commit(A, B, lm, m3),        % A never decided m3
    assertion(wait_for(agent_property(B, lm, status(in_doubt(m3, _))), 300)),
    with_node(B, agent_resolve(lm, discard)),
    with_node(B, list_agents(L)),
    assertion(L == []).

:- end_tests(lost_messages).

:- begin_tests(persistence).

test(save_and_load_state, [cleanup((stop_all([A,B]), delete_file(F)))]) :-
    tmp_file(state, F),
    node_start(localhost:0, A, [default(false), token(test)]),
    node_start(localhost:0, B, [default(false), token(test)]),
    with_node(A, ( create_mobile_agent(p1, cloner, []),
                   add_payload(p1, [(counter,2)]),
                   save_tartarus_state(F) )),
    with_node(B, ( load_tartarus_state(F), list_agents(L) )),
    assertion(L == [p1]),
    agent_property(B, p1, module(M)),
    assertion(M:counter(p1, 0)).

:- end_tests(persistence).

% --- seams: accessors, same-node test, remote errors, resource hook ---

:- dynamic user:module_event_seen/1.
seam_event(platform, _Link, X) :-
    assertz(user:module_event_seen(X)).

:- multifile node:platform_request/4.
node:platform_request(test_ctx, Ctx, ok(ctx(Node, Auth)), true) :-
    node:ctx_node(Ctx, Node),
    ( node:ctx_authenticated(Ctx) -> Auth = true ; Auth = false ).

:- begin_tests(seams).

test(node_listens_at, [cleanup(stop_all([N]))]) :-
    node_start(localhost:0, N, [default(false), token(test)]),
    port(N, P),
    assertion(node:node_listens_at(N, localhost:P)),
    assertion(node:node_listens_at(N, '127.0.0.1':P)),
    assertion(node:node_listens_at(N, ('127.0.0.1', P))),
    assertion(node:node_listens_at(N, P)),
    P1 is P + 1,
    assertion(\+ node:node_listens_at(N, localhost:P1)),
    assertion(\+ node:node_listens_at(N, '127.0.0.9':P)),
    assertion(node:node_for_address('127.0.0.1':P, N)).

test(ctx_accessors, [cleanup(stop_all([N]))]) :-
    node_start(localhost:0, N, [token(s), default(false)]),
    port(N, P),
    transport_request(localhost:P, test_ctx, R1, []),
    assertion(R1 == ctx(N, false)),
    transport_request(localhost:P, test_ctx, R2, [tokens([s])]),
    assertion(R2 == ctx(N, true)).

test(module_platform_event, [cleanup(stop_all([B]))]) :-
    node_start(localhost:0, B, [default(false), token(test)]),
    port(B, PB),
    platform_event(plunit_seams:seam_event/3),
    agent_post(localhost:PB, platform, seam_event, x, [7]),
    assertion(wait_for(user:module_event_seen(7))).

test(remote_error_prints_address, [cleanup(stop_all([N]))]) :-
    node_start(localhost:0, N, [default(false), token(test)]),
    port(N, P),
    catch(transport_request(localhost:P, post(nobody, hello, x, []), _, []), E, true),
    assertion(E = error(existence_error(agent, nobody), remote(localhost:P))),
    platform_errors:message_text(E, Text),
    format(string(Expected), "(at localhost:~w)", [P]),
    assertion(sub_string(Text, _, _, 0, Expected)).

test(record_hop, [cleanup(stop_all([N]))]) :-
    node_start(localhost:0, N, [default(false), token(test)]),
    with_node(N, create_mobile_agent(h1, walker, [])),
    assertion(agents:agent_record_hop(N, h1, hop(a, b, 1.0, 1.5))),
    agents:agent_hop_times(N, h1, Ms),
    assertion(Ms == [500.0]),
    assertion(\+ agents:agent_record_hop(N, nobody, hop(a, b, 1.0, 1.5))).

test(record_hop_keeps_the_last_100, [cleanup(stop_all([N]))]) :-
    node_start(localhost:0, N, [default(false), token(test)]),
    with_node(N, create_mobile_agent(h2, walker, [])),
    forall(between(1, 150, I),
           ( T1 is 1.0 + I / 1000,
             agents:agent_record_hop(N, h2, hop(a, b, 1.0, T1)) )),
    agents:agent_hop_times(N, h2, Ms),
    length(Ms, Len),
    assertion(Len == 100),
    Ms = [First|_], last(Ms, Last),
    assertion(abs(First - 51.0) < 1.0e-6),
    assertion(abs(Last - 150.0) < 1.0e-6).

test(add_facts_travel_as_payload, [cleanup(stop_all([N]))]) :-
    node_start(localhost:0, N, [default(false), token(test)]),
    with_node(N, create_mobile_agent(f1, walker, [])),
    agents:agent_add_facts(N, f1, [state_of(f1, s{a:1}), other(f1)]),
    agent_property(N, f1, payload(Payload)),
    assertion(Payload == [state_of/2, other/1]),
    agents:agent_export(N, f1, Record),
    arg(7, Record, Clauses),
    assertion(memberchk((state_of(f1, s{a:1}) :- true), Clauses)).

%   agent_export/3 reads a predicate of one fact by calling it, any
%   other by decompiling: the record must be what clause/2 gives for
%   every shape (one fact with shared variables, several facts, a rule,
%   a fact and a rule, an empty predicate). Control: the same clauses
%   decompiled one by one.
test(export_equals_decompiled, [cleanup(stop_all([N]))]) :-
    node_start(localhost:0, N, [default(false), token(test)]),
    with_node(N, create_mobile_agent(x1, walker, [])),
    agents:agent_add_facts(N, x1, [one(f(A, A, _), [1.5, 2.5]), two(1), two(2)]),
    agents:agent_module(N, x1, M),
    assertz(M:(rule(X) :- two(X))),
    assertz(M:mixed(0)),
    assertz(M:(mixed(X) :- X > 1)),
    dynamic(M:empty/1),
    agents:agent_export(N, x1, Record),
    arg(7, Record, Clauses),
    arg(6, Record, Preds),
    findall((H:-B), ( member(F/Ar, Preds), functor(H, F, Ar), clause(M:H, B) ),
            Expected),
    assertion(Clauses =@= Expected),
    assertion(memberchk((one(f(V, V, _), [1.5, 2.5]) :- true), Clauses)),
    assertion(memberchk((mixed(_) :- _ > 1), Clauses)),
    assertion(memberchk(empty/1, Preds)),
    assertion(\+ memberchk((empty(_) :- _), Clauses)),
    retract(M:one(_, _)),
    agents:agent_export(N, x1, Record2),
    arg(7, Record2, Clauses2),
    assertion(\+ memberchk((one(_, _) :- _), Clauses2)).

:- end_tests(seams).

:- begin_tests(robot_resources).

:- use_module('../../platform_pl/robot_resources').
:- use_module(memory_robots).

test(unknown_robot, [ setup(memory_robots_start([r1-[1.0, 2.0]])),
                      cleanup(memory_robots_stop),
                      error(existence_error(robot, r9)) ]) :-
    get_robot_table(r9, _, []).

test(read_write, [ setup(memory_robots_start([r1-[1.0, 2.0]])),
                   cleanup(memory_robots_stop) ]) :-
    get_robot_table(r1, T, [timeout(1)]),
    assertion(T == qtable([1, 2], [1.0, 2.0])),
    get_robot_tables(r1, T2, V, []),
    assertion(T2 == T),
    assertion(V == qtable([1, 2], [1.0, 1.0])),
    set_robot_table(r1, qtable([1, 2], [5.0, 6.0]), []),
    assertion(memory_robot_table(r1, [5.0, 6.0])),
    assertion(hosted_robot(r1, [algo(test), shape([1, 2])])).

test(bad_arguments, [ setup(memory_robots_start([r1-[1.0, 2.0]])),
                      cleanup(memory_robots_stop) ]) :-
    catch(get_robot_table(_, _, []), E1, true),
    assertion(E1 = error(instantiation_error, _)),
    catch(get_robot_table(r1, _, nolist), E2, true),
    assertion(E2 = error(type_error(list, nolist), _)),
    catch(set_robot_table(r1, _, []), E3, true),
    assertion(E3 = error(instantiation_error, _)).

test(hook_error_passes_through, [ setup(memory_robots_start([r1-[1.0, 2.0]])),
                                  cleanup(memory_robots_stop),
                                  error(type_error(qtable, foo(bar))) ]) :-
    set_robot_table(r1, foo(bar), []).

:- end_tests(robot_resources).
