/*  plunit tests of the run-slot, idle and per-peer bounds of agent_bounds.pl
    (agent_wall_limit, bounds_park/1, agent_idle_limit, max_agents_per_peer,
    peer_post_limit) on in-process nodes. Agents sent between nodes of one
    process count as `local`; an agent from a peer is installed here with
    bounds_install/5 as migration.pl does. The multi-process attack (peers
    told apart by their TLS certificates) is tests/security/test_slots.py.
*/
:- use_module('../../platform_pl/tartarus').
:- use_module('../../platform_pl/agent_bounds').
:- use_module('../../platform_pl/agents',
              [agent_exists/2, agent_property/3, agent_export/3, agent_set_status/3,
               agent_execute/4]).
:- use_module('../../platform_pl/transport', [transport_request/4]).
:- use_module(library(plunit)).

:- dynamic seen/1.

:- multifile user:message_hook/3.
:- dynamic user:message_hook/3.
:- asserta((user:message_hook(dfrl_bounds(M), warning, _) :- assertz(seen(M)))).
:- asserta((user:message_hook(dfrl(agent_crashed(_, _, _)), warning, _))).

:- dynamic long_sleeper/3, parker/3, good/3, ran/1, idler/3, listener/3, asker/3,
    silent_port/1.
%   blocked in remote_agents/3 on a listener that never says hello, with
%   timeouts of an hour
asker(guid, _, main) :-
    user:silent_port(P),
    catch(remote_agents(localhost:P, _, [connect_timeout(3600), reply_timeout(3600)]),
          E, ( E = '$dfrl_bound'(_) -> throw(E) ; true )),
    assertz(user:ran(asked(guid))).

%   A TCP listener that accepts and stays silent.
silent_listener(listener(Socket, Thread), Port) :-
    tcp_socket(Socket),
    tcp_setopt(Socket, reuseaddr),
    tcp_bind(Socket, localhost:Port),
    tcp_listen(Socket, 16),
    thread_create(silent_loop(Socket, []), Thread, []).
silent_loop(Socket, Held) :-
    (   catch(tcp_accept(Socket, Client, _), _, fail)
    ->  silent_loop(Socket, [Client|Held])
    ;   forall(member(C, Held), catch(tcp_close_socket(C), _, true))
    ).
silent_stop(listener(Socket, Thread)) :-
    catch(tcp_close_socket(Socket), _, true),
    catch(thread_signal(Thread, throw(stop)), _, true),
    catch(thread_join(Thread, _), _, true).
long_sleeper(guid, _, main) :- sleep(30), assertz(user:ran(slept(guid))).
%   node code (trusted) that waits parked: its wait holds no slot
parker(guid, _, main) :-
    bounds_park(sleep(1.5)),
    assertz(user:ran(parked(guid))).
good(guid, _, main) :- assertz(user:ran(guid)).
idler(guid, _, main).
listener(guid, _, main).
listener(guid, _, ping(N)) :- assertz(user:ran(ping(N))).

wait_for(G) :- wait_for(G, 300).
wait_for(G, N) :- ( call(G) -> true ; N > 0 -> sleep(0.02), N1 is N-1, wait_for(G, N1) ; fail ).

node(Options, N) :-
    node_start(localhost:0, N, [token(5), default(false)|Options]).

link(N, (H, P)) :- node_property(N, address(H:P)).

send(From, To, Name, Handler) :-
    with_node(From, create_mobile_agent(Name, Handler, [5])),
    link(To, Link),
    with_node(From, move_agent(Name, Link)).

%   Install on To a copy of agent Name (made on From) as if it had come
%   from Peer, and start it, as migration.pl does for a transfer; return
%   once its main handler is done.
arrive(From, To, Name, Handler, Peer) :-
    with_node(From, create_mobile_agent(Name, Handler, [5])),
    agent_export(From, Name, Record),
    bounds_install(To, Record, idle, Name, Peer),
    node_property(From, address(Source)),
    bounds_arrived(To, Name, Source, Peer),
    link(To, Link),
    agent_execute(To, Name, Link, main),
    assertion(wait_for(agent_property(To, Name, status(idle)))).

%   Installed and never started: the monitor's idle poll (10 s) finds it.
arrive_unstarted(From, To, Name, Handler, Peer) :-
    with_node(From, create_mobile_agent(Name, Handler, [5])),
    agent_export(From, Name, Record),
    bounds_install(To, Record, idle, Name, Peer),
    node_property(From, address(Source)),
    bounds_arrived(To, Name, Source, Peer).

cleanup(Nodes) :-
    retractall(seen(_)),
    retractall(ran(_)),
    forall(member(N, Nodes), catch(node_stop(N), _, true)).

:- begin_tests(agent_slots).

test(wall_limit_stops_a_sleeper, [cleanup(cleanup([A, B]))]) :-
    node([agent_wall_limit(0.5)], A),
    node([], B),
    get_time(T0),
    send(B, A, z1, long_sleeper),
    assertion(wait_for(agent_bound_report(B, z1, bound(wall(0.5), _, _, _)), 250)),
    get_time(T1),
    assertion(T1 - T0 < 4),
    assertion(wait_for(\+ agent_exists(A, z1))),
    assertion(\+ ran(slept(z1))).

%   Control: without the bound the sleeper keeps its slot.
test(wall_limit_infinite_control, [cleanup(cleanup([A, B]))]) :-
    node([agent_wall_limit(infinite)], A),
    node([], B),
    send(B, A, z1, long_sleeper),
    sleep(1.5),
    assertion(agent_property(A, z1, status(running(_)))),
    assertion(\+ agent_bound_report(B, z1, _)).

%   A call parked in bounds_park/1 gives its slot back (g1 runs while it
%   waits) and its parked time is not wall time (it is not stopped).
test(parked_call_frees_its_slot, [cleanup(cleanup([A, B]))]) :-
    node([max_running_agents(1), agent_wall_limit(0.5)], A),
    node([], B),
    send(B, A, p1, parker),
    sleep(0.3),
    send(B, A, g1, good),
    assertion(wait_for(ran(g1), 40)),           % within 0.8 s: p1 still parked
    assertion(\+ ran(parked(p1))),
    assertion(wait_for(ran(parked(p1)), 200)),
    assertion(\+ agent_bound_report(B, p1, _)).

%   Parked time is bounded too (agent_idle_limit).
test(parked_time_bounded, [cleanup(cleanup([A, B]))]) :-
    node([agent_idle_limit(0.5)], A),
    node([], B),
    send(B, A, p1, parker),
    assertion(wait_for(agent_bound_report(B, p1, bound(idle(0.5), _, _, _)), 150)),
    assertion(\+ ran(parked(p1))).

test(idle_agent_from_a_peer_expires, [cleanup(cleanup([A, B]))]) :-
    node([agent_idle_limit(0.5)], A),
    node([], B),
    arrive(B, A, i1, idler, tls(mallory)),
    with_node(A, create_mobile_agent(mine, idler, [5])),  % made here: exempt
    assertion(agent_exists(A, i1)),
    assertion(wait_for(\+ agent_exists(A, i1), 200)),
    assertion(wait_for(agent_bound_report(B, i1, bound(idle(0.5), _, _, _)))),
    sleep(0.6),
    assertion(agent_exists(A, mine)),
    bounds_statistics(S),
    assertion(S.idle_expired >= 1).

%   An agent that is not idle (here: staged, i.e. in custody) is kept;
%   posted events restart its clock.
test(only_idle_agents_expire, [cleanup(cleanup([A, B]))]) :-
    node([agent_idle_limit(0.6)], A),
    node([], B),
    arrive(B, A, s1, idler, ip(10,0,0,1)),
    agent_set_status(A, s1, staged(m1)),
    arrive(B, A, l1, listener, ip(10,0,0,1)),
    link(A, Link),
    forall(between(1, 6, I),
           ( sleep(0.2), with_node(A, post_agent(platform, Link, [listener, l1, x, ping(I)])) )),
    assertion(agent_exists(A, l1)),
    assertion(agent_exists(A, s1)),
    assertion(wait_for(\+ agent_exists(A, l1), 200)).

test(idle_limit_infinite_control, [cleanup(cleanup([A, B]))]) :-
    node([agent_idle_limit(infinite)], A),
    node([], B),
    arrive(B, A, i1, idler, tls(mallory)),
    sleep(1.0),
    assertion(agent_exists(A, i1)).

test(max_agents_per_peer, [cleanup(cleanup([A, B]))]) :-
    node([max_agents_per_peer(2)], A),
    node([], B),
    arrive(B, A, m1, idler, tls(mallory)),
    arrive(B, A, m2, idler, tls(mallory)),
    catch(arrive(B, A, m3, idler, tls(mallory)), E, true),
    assertion(E = error(resource_error(peer_agents), _)),
    assertion(\+ agent_exists(A, m3)),
    arrive(B, A, a1, idler, tls(alice)),            % another peer
    assertion(agent_exists(A, a1)),
    arrive(B, A, l1, idler, local),                 % a node of this process
    assertion(agent_property(A, m1, peer(tls(mallory)))),
    assertion(agent_property(A, l1, peer(local))).

%   Posts from a peer over peer_post_limit are refused and counted.
test(peer_post_limit, [cleanup(cleanup([A, B]))]) :-
    node([peer_post_limit(5)], A),
    node([], B),
    send(B, A, l1, listener),
    node_property(A, address(Addr)),
    bounds_statistics(S0),
    findall(R,
            ( between(1, 8, I),
              catch(( transport_request(Addr, post(l1, listener, x, [ping(I)]), _,
                                        [tokens([5])]),
                      R = ok ),
                    error(E, _), R = E) ),
            Rs),
    Rs = [R1, R2, R3, R4, R5, R6, R7, R8],
    assertion([R1, R2, R3, R4, R5] == [ok, ok, ok, ok, ok]),
    assertion(R6 == resource_error(posts)),
    assertion(R7 == resource_error(posts)),
    assertion(R8 == resource_error(posts)),
    bounds_statistics(S1),
    assertion(S1.refused_posts - S0.refused_posts =:= 3),
    assertion(wait_for(ran(ping(5)))),
    assertion(\+ ran(ping(6))).

%   A blocking call the agent API allows (remote_agents/3, timeouts of an
%   hour, a listener that never answers) is cut by the wall bound.
test(wall_limit_cuts_a_blocked_remote_call,
     [cleanup(( cleanup([A, B]), silent_stop(L), retractall(user:silent_port(_)) ))]) :-
    silent_listener(L, Port),
    assertz(user:silent_port(Port)),
    node([agent_wall_limit(1)], A),
    node([], B),
    send(B, A, q1, asker),
    assertion(wait_for(agent_bound_report(B, q1, bound(wall(1), _, _, _)), 250)),
    assertion(\+ ran(asked(q1))).

test(unstarted_agent_found_by_the_idle_poll, [cleanup(cleanup([A, B]))]) :-
    node([agent_idle_limit(0.5)], A),
    node([], B),
    sleep(0.5),                                 % the monitor is waiting, no call runs
    arrive_unstarted(B, A, u1, idler, tls(mallory)),
    assertion(wait_for(\+ agent_exists(A, u1), 800)).

:- end_tests(agent_slots).
