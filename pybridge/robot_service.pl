:- module(robot_service,
          [ robot_service_request/1    % ?Request
          ]).
:- use_module(robot_bridge, [bridge_service_call/3]).
:- use_module('../platform_pl/node', [ctx_authenticated/1, ctx_node/2]).
:- autoload(library(error),
            [must_be/2, domain_error/2, permission_error/3, type_error/2]).
:- autoload(library(http/json), [atom_json_dict/3]).

/** <module> The robot process as a service: `dfrl_robot(Request)` platform requests

A long-lived robot process (`dfrl robot`, dfrl.experiments.robot_host.service)
answers the platform request dfrl_robot(Request) of peers that proved one
of its node's tokens; anyone else gets permission_error(access,
robot_service, Node). A peer sends it with transport_request/4:

```
?- transport_request('10.0.0.7':7001, dfrl_robot(status), Status,
                     [tokens([1111])]).
Status = _{robot:r1, state:"running", iteration:812, ...}.
```

Requests (checked here; anything else is domain_error(dfrl_robot_request, R)):

  | Request                       | Reply                                    |
  |-------------------------------|------------------------------------------|
  | status                        | a dict: robot, state, experiment, iteration, iterations, shares, error, address, node_id |
  | configure(Json)               | true (Json: a string holding a JSON object) |
  | start                         | true                                     |
  | stop                          | true                                     |
  | files                         | [file(Name, Size), ...]                  |
  | fetch(Name, Offset, Max)      | chunk(Base64, Eof), Max in 1..1048576    |

The request is handed to the robot process's Python main thread through the
bridge's service queue (bridge_service_call/3), which the process serves
between two control steps and while idle, in every pacing mode. Nothing of
the request is called; the Python side answers with ok(Term), ok(json(Text))
(a JSON object, replied as a dict) or error(Formal), which the peer
receives as error(Formal, remote(Address)).
*/

:- multifile node:platform_request/4.

node:platform_request(dfrl_robot(Request), Ctx, Reply, true) :-
    robot_service_reply(Request, Ctx, Reply).

%!  robot_service_request(?Request) is nondet.
%
%   Request is a well-formed dfrl_robot/1 argument (its shape only; see
%   the table above). Enumerates the argument-free requests.

robot_service_request(status).
robot_service_request(start).
robot_service_request(stop).
robot_service_request(files).
robot_service_request(configure(Json)) :-
    (string(Json) ; atom(Json)), !.
robot_service_request(fetch(Name, Offset, Max)) :-
    (atom(Name) ; string(Name)),
    integer(Offset), Offset >= 0,
    integer(Max), Max >= 1, Max =< 1048576.

robot_service_reply(Request, Ctx, Reply) :-
    (   ctx_authenticated(Ctx)
    ->  true
    ;   ctx_node(Ctx, Node),
        permission_error(access, robot_service, Node)
    ),
    check_request(Request, Checked),
    bridge_service_call(Checked, Answer, []),
    answer_reply(Answer, Reply).

check_request(Request, _) :-
    var(Request),
    !,
    domain_error(dfrl_robot_request, Request).
check_request(configure(Json), configure(Text)) :-
    !,
    (   (string(Json) ; atom(Json))
    ->  atom_string(Json, Text)
    ;   type_error(string, Json)
    ).
check_request(Request, Request) :-
    robot_service_request(Request),
    !.
check_request(Request, _) :-
    domain_error(dfrl_robot_request, Request).

answer_reply(ok(json(Text)), ok(Dict)) :-
    !,
    must_be(string, Text),
    atom_json_dict(Text, Dict, [value_string_as(string)]).
answer_reply(ok(Result), ok(Result)) :-
    !.
answer_reply(error(Formal), _) :-
    !,
    throw(error(Formal, _)).
answer_reply(Other, _) :-
    domain_error(robot_service_answer, Other).

:- multifile prolog:error_message//1.

prolog:error_message(robot_config_error(Message)) -->
    [ 'Bad robot configuration: ~w'-[Message] ].
