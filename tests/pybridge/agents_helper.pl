:- module(bridge_test_agents, [spawn/2, agent_result/2]).
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
