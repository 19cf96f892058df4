/*  The processes of the chaos benchmark (experiments/tools/bench/chaos.py).

    swipl chaos_node.pl node PORT STORE TOKEN ROUTES [AGENTS]
        A platform node on 127.0.0.1:PORT with store(STORE) and short
        timeouts. ROUTES is "J=PORT,J=PORT,...": the addresses (fault
        proxies) through which this node's agents go to node J. AGENTS
        ("a,b,...", first start only) are created here and started. Prints
        "CHAOS listening on 127.0.0.1:PORT" and serves until killed.
        Requests: chaos_pause(Bool) (agents wait before their next move),
        chaos_census (agent(Name, Status, Hops) per agent, from
        custody_agents/2), chaos_create(Name, Kind) (a `hopper` that
        starts moving or a `parcel` that stays idle wherever it arrives),
        chaos_move(Name, Port) (agent_move/3 of an idle agent to
        127.0.0.1:Port; answers moved or the error).

    swipl chaos_node.pl console TOKEN
        JSON lines on stdin, one answer line each on stdout:
        {"op":"census","ports":[P,...]} ->
            {"nodes":[{"port":P,"ok":true,"agents":[{"name":N,"status":S,"hops":H}]}
                      | {"port":P,"ok":false,"error":Text}]}
        {"op":"pause","ports":[P,...],"paused":Bool} -> {"nodes":[{"port":P,"ok":Bool}]}
        {"op":"create","port":P,"agent":A,"kind":"hopper"|"parcel"} -> {"ok":Bool,...}
        {"op":"move","port":P,"agent":A,"to":Q} -> {"ok":true} | {"ok":false,"error":Text}

    Every agent is a hopper: after a pause of 20-120 ms it moves to a
    random other node; a move that fails is tried again (at most 100000
    times) after 50 ms.
*/
:- use_module('../../../platform_pl/tartarus').
:- use_module('../../../platform_pl/transport', [transport_request/4]).
:- use_module('../../../platform_pl/secrets', [take_env_tokens/1]).
:- use_module(library(http/json)).
:- use_module(library(main)).

:- initialization(main, main).

:- dynamic user:chaos_route/2, user:chaos_paused/0.

%   Arriving hoppers run in the sandbox (platform_pl/code_safety.pl): this
%   node extends the agent API with reading its route table and pause flag.
:- multifile sandbox:safe_primitive/1.
sandbox:safe_primitive(user:chaos_route(_, _)).
sandbox:safe_primitive(user:chaos_paused).
:- dynamic chaos_hops/2.

%   The token comes in the environment (DFRL_TOKEN), never on the
%   command line.
main([node, Port0, Store, Routes | Rest]) :-
    env_token(Token),
    (   getenv('DFRL_CHAOS_DEBUG', _)
    ->  debug(dfrl(custody))
    ;   true
    ),
    atom_number(Port0, Port),
    parse_routes(Routes),
    node_start('127.0.0.1':Port, Node,
               [ token(Token), store(Store), default(true),
                 connect_timeout(1), reply_timeout(1.5), commit_timeout(1),
                 settle_period(0.5), idle_timeout(30)
               ]),
    migration:migration_start(Node),
    (   Rest = [Agents]
    ->  atomic_list_concat(Names, ',', Agents),
        forall(member(N, Names), create_agent(Node, N, hopper))
    ;   true
    ),
    format("CHAOS listening on 127.0.0.1:~w~n", [Port]),
    flush_output,
    thread_get_message(_).
main([console]) :-
    env_token(Token),
    set_stream(user_output, buffer(line)),
    console_loop(Token).

env_token(Token) :-
    (   take_env_tokens([Token|_])
    ->  true
    ;   format(user_error, "chaos_node: DFRL_TOKEN is not set~n", []),
        halt(2)
    ).

parse_routes(Text) :-
    atomic_list_concat(Parts, ',', Text),
    forall(member(P, Parts),
           ( atomic_list_concat([J0, Port0], '=', P),
             atom_number(J0, J), atom_number(Port0, Port),
             assertz(user:chaos_route(J, Port)) )).

create_agent(Node, Name, Kind) :-
    (   agents:agent_exists(Node, Name)
    ->  true
    ;   node_property(Node, tokens(Tokens)),
        handler(Kind, Handler),
        assertz(chaos_hops(guid, 0)),
        create_mobile_agent(Name, Handler, Tokens),
        add_payload(Name, [(chaos_hops, 2)]),
        retractall(chaos_hops(guid, _)),
        (   Kind == hopper
        ->  node_property(Node, link(Link)),
            execute_agent(Name, Link, Handler)
        ;   true
        )
    ).

handler(hopper, chaos_hopper).
handler(parcel, chaos_parcel).

%   A parcel counts its arrivals and rests.
chaos_parcel(guid, _Link, main) :-
    retract(chaos_hops(guid, H0)),
    H is H0 + 1,
    assertz(chaos_hops(guid, H)).

chaos_hopper(guid, _Link, main) :-
    retract(chaos_hops(guid, H0)),
    H is H0 + 1,
    assertz(chaos_hops(guid, H)),
    between(1, 100000, _),
    wait_unpaused(2400),
    Pause is 0.02 + random_float * 0.1,
    sleep(Pause),
    findall(P, user:chaos_route(_, P), Ports),
    random_member(Port, Ports),
    catch(move_agent(guid, ('127.0.0.1', Port)), error(_, _), ( sleep(0.05), fail )),
    !.

wait_unpaused(0) :- !.
wait_unpaused(N) :-
    (   user:chaos_paused
    ->  sleep(0.05),
        N1 is N - 1,
        wait_unpaused(N1)
    ;   true
    ).

:- multifile node:platform_request/4.

node:platform_request(chaos_pause(Bool), _Ctx, ok(Bool), true) :-
    (   Bool == true
    ->  ( user:chaos_paused -> true ; assertz(user:chaos_paused) )
    ;   retractall(user:chaos_paused)
    ).
node:platform_request(chaos_create(Name, Kind), Ctx, ok(created), true) :-
    must_be(atom, Name),
    must_be(oneof([hopper, parcel]), Kind),
    node:ctx_node(Ctx, Node),
    create_agent(Node, Name, Kind).
node:platform_request(chaos_move(Name, Port), Ctx, Reply, true) :-
    must_be(atom, Name),
    must_be(integer, Port),
    node:ctx_node(Ctx, Node),
    catch(( with_node(Node, agent_move(Name, '127.0.0.1':Port, [])),
            Reply = ok(moved) ),
          E, Reply = error(E)).
node:platform_request(chaos_census, Ctx, ok(Agents), true) :-
    node:ctx_node(Ctx, Node),
    custody:custody_agents(Node, List),
    findall(agent(Name, Status, Hops),
            ( member(agent(Name, Status), List),
              agent_hops(Node, Name, Hops)
            ),
            Agents).

agent_hops(Node, Name, Hops) :-
    (   catch(agents:agent_module(Node, Name, M), _, fail),
        catch(M:chaos_hops(Name, H), _, fail)
    ->  Hops = H
    ;   Hops = 0
    ).

		 /*******************************
		 *            CONSOLE		*
		 *******************************/

console_loop(Token) :-
    catch(json_read_dict(user_input, Req, [end_of_file(eof)]), E,
          ( print_message(error, E), Req = eof )),
    (   Req == eof
    ->  true
    ;   catch(answer(Req, Token, Out), E2,
              ( format(string(Text), '~p', [E2]), Out = _{error: Text} )),
        json_write_dict(user_output, Out, [width(0)]),
        nl(user_output),
        flush_output(user_output),
        console_loop(Token)
    ).

answer(Req, _Token, _{nodes: Nodes}) :-
    Req.op == "census",
    !,
    findall(N, ( member(P, Req.ports), census(P, N) ), Nodes).
answer(Req, _Token, Out) :-
    Req.op == "create",
    !,
    atom_string(Name, Req.agent),
    atom_string(Kind, Req.kind),
    request(Req.port, chaos_create(Name, Kind), Out).
answer(Req, _Token, Out) :-
    Req.op == "move",
    !,
    atom_string(Name, Req.agent),
    request(Req.port, chaos_move(Name, Req.to), Out).
answer(Req, _Token, _{nodes: Nodes}) :-
    Req.op == "pause",
    !,
    ( Req.paused == true -> B = true ; B = false ),
    findall(_{port: P, ok: Ok},
            ( member(P, Req.ports),
              (   catch(transport_request('127.0.0.1':P, chaos_pause(B), _,
                                          [connect_timeout(1), reply_timeout(2)]), _, fail)
              ->  Ok = true
              ;   Ok = false
              )
            ),
            Nodes).

request(Port, Request, Out) :-
    catch(( transport_request('127.0.0.1':Port, Request, _,
                              [connect_timeout(1), reply_timeout(10)]),
            Out = _{ok: true}
          ),
          E,
          ( format(string(Text), '~p', [E]),
            Out = _{ok: false, error: Text}
          )).

census(Port, Node) :-
    catch(transport_request('127.0.0.1':Port, chaos_census, Agents,
                            [connect_timeout(1), reply_timeout(3)]),
          E, true),
    (   var(E)
    ->  findall(_{name: N, status: S, hops: H},
                member(agent(N, S, H), Agents), List),
        Node = _{port: Port, ok: true, agents: List}
    ;   format(string(Text), '~p', [E]),
        Node = _{port: Port, ok: false, error: Text}
    ).
