:- module(bridge_test_agents, [spawn/2, agent_result/2, stress/4]).
/** <module> Test helper: run a goal in a fresh Prolog thread (an "agent") and keep its outcome

agent_result(Alias, Result) gives true(Goal) (Goal with its bindings), false or
error(E) once the thread has finished, and joins it.
*/
:- dynamic result_/2.

spawn(Alias, Goal) :-
    retractall(result_(Alias, _)),
    thread_create(run(Alias, Goal), _, [alias(Alias)]).

run(Alias, Goal) :-
    catch(( call(user:Goal) -> R = true(Goal) ; R = false ), E, R = error(E)),
    assertz(result_(Alias, R)).

agent_result(Alias, Result) :-
    retract(result_(Alias, Result)),
    thread_join(Alias, _).

%!  stress(+Robot, +K, +N, -Mixed) is det.
%
%   N times: write a table filled with K, read the table back. Mixed counts
%   the reads that were not uniform (a torn snapshot).
stress(Robot, K, N, Mixed) :-
    robot_bridge:bridge_robot(Robot, Props),
    memberchk(shape([S, A]), Props),
    Len is S*A,
    F is float(K),
    length(Values, Len),
    maplist(=(F), Values),
    aggregate_all(count,
                  ( between(1, N, _),
                    robot_bridge:set_qtable(Robot, qtable([S, A], Values)),
                    robot_bridge:get_qtable(Robot, qtable(_, Got)),
                    \+ uniform(Got)
                  ),
                  Mixed).

uniform([X|T]) :- maplist(==(X), T).
