/*  A peer that answers dfrl_robot(Request) platform requests in the shapes
    of contract K5, for testing the console node's `robot` op on its own
    (the real service, `dfrl robot`, is tested in tests/multihost and by
    the robot node's tests). Consult it into a node (node_main.pl
    --consult). It refuses unauthenticated peers, echoes a configure, and
    serves one file, "metrics_r1.csv", in chunks.
*/
:- use_module(library(base64), [base64/2]).
:- multifile node:platform_request/4.
:- dynamic peer_configured/1.

peer_file("robot,iteration\nr1,1\nr1,2\n").

node:platform_request(dfrl_robot(R), Ctx, Reply, true) :-
    (   node:ctx_authenticated(Ctx)
    ->  catch(( peer(R, Answer) -> Reply = ok(Answer)
              ; Reply = error(error(domain_error(robot_request, R), _)) ),
              E, Reply = error(E))
    ;   Reply = error(error(permission_error(access, robot, R), _))
    ).

peer(status, _{robot:r1, state:State, experiment:null, iteration:7, iterations:10,
               shares:1, error:null, address:["127.0.0.1", 0], node_id:"00"}) :-
    (   peer_configured(_) -> State = configured ; State = idle ).
peer(configure(Json), true) :-
    string(Json),
    retractall(peer_configured(_)),
    assertz(peer_configured(Json)).
peer(start, true).
peer(stop, true).
peer(files, [file('metrics_r1.csv', Size)]) :-
    peer_file(T), string_length(T, Size).
peer(fetch(Name, Offset, Max), chunk(Data, Eof)) :-
    atom(Name), Name == 'metrics_r1.csv',
    peer_file(T), string_length(T, Size),
    Len is max(0, min(Max, Size - Offset)),
    sub_string(T, Offset, Len, _, Part),
    base64(Part, Data),
    (   Offset + Len >= Size -> Eof = true ; Eof = false ).
